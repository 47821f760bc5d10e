"""Half-space envelopes: exact sampling of the model restricted to a superset of the region.

The model is a Gaussian mixture in z-space. For a half-space ``S = {z : a.z <= b}`` both
the mass and exact draws of the mixture restricted to S are cheap:

* component k: ``s = a.z ~ N(m_k, v_k)`` with ``m_k = a.mu_k``, ``v_k = a' Sigma_k a``;
  ``P_k(S) = Phi((b - m_k) / sqrt(v_k))`` (in log space, ``log_ndtr``, so masses of 1e-30
  stay exact), ``P(S) = sum_k w_k P_k(S)``;
* a draw: component k with probability ``w_k P_k(S) / P(S)``; ``s`` from the normal
  truncated to ``s <= b`` by inversion in log space (``ndtri_exp``); then ``z`` from the
  component conditioned on ``a.z = s`` (draw ``y ~ N(mu_k, Sigma_k)`` and set
  ``z = y + Sigma_k a (s - a.y) / v_k``).

If a region A lies inside S, draws from ``p | S`` kept when inside A are exact draws from
``p | A`` with acceptance ``P(A | S)``, and ``P(A) = P(S) P(A | S)`` is estimated with the
exact binomial interval of ``P(A | S)`` — accurate however rare A is, as long as S is tight.

Envelopes found from a region's constraints (the tightest, i.e. smallest P(S), is used):

* a constraint on a model feature, ``x < v`` or ``x > v``: the transforms are increasing,
  so it is exactly the half-space ``z_j < (g(v) - loc) / scale`` (or ``>``);
* ``ttc < c`` (or ``<=``) with features ``dv`` (identity transform) and ``gap``: A needs
  ``dv > 0`` and ``gap < c dv``. With ``gap`` on identity this is the half-space
  ``gap - c dv <= 0``; with ``gap`` on log it is ``log gap <= log c + log dv``, and since
  log is concave, ``log dv <= log d0 + dv / d0 - 1`` for every ``d0 > 0``: the tangent
  half-space ``log gap - dv / d0 <= log(c d0) - 1`` contains A. ``d0`` is chosen to
  minimise P(S) (bounded scalar minimisation over log d0, deterministic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar
from scipy.special import log_ndtr, logsumexp, ndtri_exp

from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Constraint, Region

__all__ = ["HalfSpace", "find_envelope"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class HalfSpace:
    """``S = {z : a.z <= b}`` in the model's z-space, with the model's mass in it.

    Attributes
    ----------
    a : ndarray of shape (d,)
    b : float
    log_mass : float
        log P(S) under the model (exact up to rounding).
    source : str
        The constraint it came from (for diagnostics).
    """

    a: FloatArray
    b: float
    log_mass: float
    source: str

    @property
    def mass(self) -> float:
        return math.exp(self.log_mass)

    def contains(self, z: FloatArray) -> NDArray[np.bool_]:
        return np.asarray(z @ self.a <= self.b, dtype=bool)

    def sample_z(self, model: CutInGMM, n: int,
                 rng: np.random.Generator | np.random.RandomState) -> FloatArray:
        """``n`` exact draws of the model restricted to S, shape (n, d).

        ``rng`` is advanced: a Generator, or emcee's RandomState (same method names).
        """
        m, sd, log_pk = component_projections(model, self.a, self.b)
        log_w = np.log(np.where(model.weights_ > 0, model.weights_, 1e-300)) + log_pk
        w = np.exp(log_w - logsumexp(log_w))
        cdf = np.cumsum(w)
        cdf[-1] = 1.0
        labels = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(w) - 1)
        u = rng.random(n)
        e = rng.standard_normal((n, model.n_features))
        z = np.empty((n, model.n_features))
        for k in range(len(w)):
            idx = np.flatnonzero(labels == k)
            if idx.size == 0:
                continue
            # s = a.z from N(m_k, sd_k^2) truncated to s <= b, by inversion in log space
            log_u = np.log(np.where(u[idx] > 0, u[idx], 1e-300))
            s = m[k] + sd[k] * ndtri_exp(log_u + log_pk[k])
            s = np.minimum(s, self.b)
            y = model.means_[k] + e[idx] @ model.cholesky_[k].T
            sig_a = model.covariances_[k] @ self.a
            z[idx] = y + np.outer(s - y @ self.a, sig_a / (sd[k] ** 2))
        return z

    def log_q(self, model: CutInGMM, z: FloatArray) -> FloatArray:
        """Log-density of ``p | S`` in z-space (-inf outside S)."""
        out = model.log_density_z(z) - self.log_mass
        return np.where(self.contains(z), out, -np.inf)

    def to_dict(self) -> dict[str, object]:
        return {"source": self.source, "mass": self.mass, "a": self.a.tolist(), "b": self.b}


def component_projections(model: CutInGMM, a: FloatArray, b: float
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    m = model.means_ @ a
    v = np.einsum("i,kij,j->k", a, model.covariances_, a)
    sd = np.sqrt(v)
    return m, sd, log_ndtr((b - m) / sd)


def _log_mass(model: CutInGMM, a: FloatArray, b: float) -> float:
    _, _, log_pk = component_projections(model, a, b)
    log_w = np.log(np.where(model.weights_ > 0, model.weights_, 1e-300))
    return float(logsumexp(log_w + log_pk))


def _feature_halfspace(model: CutInGMM, c: Constraint) -> tuple[FloatArray, float] | None:
    if c.name not in model.features_:
        return None
    j = model.features_.index(c.name)
    tr = model.transforms_[j]
    g = tr.g(np.array([c.value]))[0]
    d = model.n_features
    a = np.zeros(d)
    if c.op in ("<", "<="):
        if not math.isfinite(g):
            return None  # e.g. log of a non-positive bound: the region is empty anyway
        a[j] = 1.0
        return a, float((g - tr.loc) / tr.scale)
    if not math.isfinite(g):
        return None
    a[j] = -1.0
    return a, float(-(g - tr.loc) / tr.scale)


def _ttc_halfspace(model: CutInGMM, c: Constraint) -> tuple[FloatArray, float] | None:
    if c.op not in ("<", "<=") or c.value <= 0:
        return None
    f = model.features_
    if "dv" not in f or "gap" not in f:
        return None
    t_dv, t_gap = model.transforms_[f.index("dv")], model.transforms_[f.index("gap")]
    if t_dv.kind != "identity" or t_gap.kind not in ("identity", "log"):
        return None
    d = model.n_features
    i_dv, i_gap = f.index("dv"), f.index("gap")
    cval = c.value
    if t_gap.kind == "identity":
        # gap - c dv <= 0 with gap = s_g z_g + l_g, dv = s_d z_d + l_d
        a = np.zeros(d)
        a[i_gap] = t_gap.scale
        a[i_dv] = -cval * t_dv.scale
        return a, float(cval * t_dv.loc - t_gap.loc)

    def plane(log_d0: float) -> tuple[FloatArray, float]:
        d0 = math.exp(log_d0)
        a = np.zeros(d)
        a[i_gap] = t_gap.scale
        a[i_dv] = -t_dv.scale / d0
        b = math.log(cval * d0) - 1.0 - t_gap.loc + t_dv.loc / d0
        return a, b

    res = minimize_scalar(lambda ld: _log_mass(model, *plane(ld)),
                          bounds=(math.log(0.05), math.log(80.0)), method="bounded",
                          options={"xatol": 1e-4})
    return plane(float(res.x))


def find_envelope(model: CutInGMM, region: Region) -> HalfSpace | None:
    """The tightest half-space envelope of ``region``'s constraints, or None.

    Only the user's constraints are used (the physical bounds are checked by rejection).
    """
    best: HalfSpace | None = None
    for c in region.constraints:
        hs = _ttc_halfspace(model, c) if c.name == "ttc" else _feature_halfspace(model, c)
        if hs is None:
            continue
        a, b = hs
        if not (np.isfinite(a).all() and math.isfinite(b)) or not np.any(a):
            continue
        log_mass = _log_mass(model, a, b)
        if best is None or log_mass < best.log_mass:
            best = HalfSpace(a=a, b=b, log_mass=log_mass, source=str(c))
    return best
