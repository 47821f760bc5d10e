"""Strata of the scenario model for stratified rare-event estimation (``sampler.methods.rare``).

The model is a Gaussian mixture in z-space, ``p = sum_k w_k N(mu_k, Sigma_k)``, so for
any region A

    P(A) = sum_s pi_s P_s(A),

over disjoint strata s of the latent (component, z) space: here component k, optionally
split by the cut-in side (``p_y1 > 0``: towards the left, ``< 0``: towards the right; the
transform of ``p_y1`` is increasing, so a side is the half-space ``z_j >= c`` or
``z_j <= c`` of z-space). ``P_s`` is component k restricted to the half-space H_s,
``pi_s = w_k P_k(H_s)`` is exact (a normal tail probability), and ``P_s`` can be sampled
exactly and mapped from a standard normal vector (so subset simulation, which works in
standard normal space, runs on it): ``u[0]`` gives the projection ``s = a.z`` from the
normal truncated to H_s by inversion in log space (``ndtri_exp``), ``u[1:]`` a draw ``y``
of component k, and ``z = y + Sigma_k a (s - a.y) / (a' Sigma_k a)`` (``y`` conditioned on
``a.z = s``, as in ``sampler.methods.envelope``). Without a side split ``z = mu_k + L_k u[1:]``.

Each stratum holds one component and one side: a region's separate modes (left and right
cut-ins, several components) fall into separate strata, and a Markov chain or kernel
density inside one stratum no longer has to find the others.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr, ndtri_exp

from sampler.methods.envelope import component_projections  # the components' masses in a half-space
from sampler.methods.problem import FloatArray
from sampler.model.gmm import CutInGMM

__all__ = ["SIDE_FEATURE", "Stratum", "halfspace_strata", "make_strata"]

#: the feature whose sign is the cut-in side (+: towards the left)
SIDE_FEATURE = "p_y1"


@dataclass(frozen=True)
class Stratum:
    """Component ``k`` of ``model`` restricted to ``{a.z <= b}`` (``a`` None: everywhere).

    Attributes
    ----------
    model : CutInGMM
    k : int
    a : ndarray (d,) or None
    b : float
    log_pk : float
        log P_k(H), the component's mass in the half-space (0 without one).
    label : str
        e.g. ``"component 1, p_y1 > 0"``.
    """

    model: CutInGMM
    k: int
    a: FloatArray | None
    b: float
    log_pk: float
    label: str

    @property
    def log_mass(self) -> float:
        """log pi_s = log w_k + log P_k(H)."""
        w = float(self.model.weights_[self.k])
        return (math.log(w) if w > 0 else -math.inf) + self.log_pk

    @property
    def mass(self) -> float:
        return math.exp(self.log_mass)

    @property
    def n_features(self) -> int:
        return self.model.n_features

    def contains(self, z: FloatArray) -> NDArray[np.bool_]:
        """Rows inside the half-space (all rows without one)."""
        if self.a is None:
            return np.ones(z.shape[0], dtype=bool)
        return np.asarray(z @ self.a <= self.b, dtype=bool)

    def log_density_z(self, z: FloatArray) -> FloatArray:
        """log-density of ``P_s`` (the component restricted to H, normalised); -inf outside
        H and for non-finite rows."""
        m = self.model
        z_a = np.atleast_2d(np.asarray(z, dtype=np.float64))
        ok: NDArray[np.bool_] = np.asarray(np.isfinite(z_a).all(axis=1), dtype=bool)
        zz = np.where(ok[:, None], z_a, 0.0)
        y = (zz - m.means_[self.k]) @ m.cholesky_inv_[self.k].T
        out = m.log_norm_[self.k] - 0.5 * np.einsum("ij,ij->i", y, y) - self.log_pk
        return np.asarray(np.where(ok & self.contains(zz), out, -np.inf), dtype=np.float64)

    def from_normal(self, u: FloatArray) -> FloatArray:
        """Standard normal rows (n, d + 1) -> exact draws of ``P_s`` (module docstring)."""
        m = self.model
        mu, chol = m.means_[self.k], m.cholesky_[self.k]
        y = mu + np.asarray(u[:, 1:]) @ chol.T
        if self.a is None:
            return np.asarray(y, dtype=np.float64)
        sig_a = m.covariances_[self.k] @ self.a
        var = float(self.a @ sig_a)
        sd = math.sqrt(var)
        mean = float(self.a @ mu)
        s = mean + sd * ndtri_exp(log_ndtr(np.asarray(u[:, 0])) + self.log_pk)
        s = np.minimum(s, self.b)
        return np.asarray(y + np.outer(s - y @ self.a, sig_a / var), dtype=np.float64)

    def sample_z(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` exact draws of ``P_s``, shape (n, d)."""
        return self.from_normal(rng.standard_normal((int(n), self.n_features + 1)))


def make_strata(model: CutInGMM, split_side: bool = True) -> list[Stratum]:
    """One stratum per component with positive weight, each split into ``p_y1 > 0`` and
    ``p_y1 < 0`` when ``split_side`` and ``p_y1`` is a model feature. The strata are
    disjoint in (component, z) and their masses sum to 1."""
    model.check_fitted()
    feats = list(model.features_)
    out: list[Stratum] = []
    side = split_side and SIDE_FEATURE in feats
    if side:
        j = feats.index(SIDE_FEATURE)
        c = float(model.transforms_[j].forward(np.zeros(1))[0][0])
    for k in range(model.n_components_):
        if not model.weights_[k] > 0:
            continue
        if not side:
            out.append(Stratum(model, k, None, math.inf, 0.0, f"component {k}"))
            continue
        mu = float(model.means_[k, j])
        sd = math.sqrt(float(model.covariances_[k, j, j]))
        e = np.zeros(model.n_features)
        e[j] = 1.0
        # p_y1 > 0 (left): z_j >= c, i.e. (-e).z <= -c;  p_y1 < 0 (right): e.z <= c
        out.append(Stratum(model, k, -e, -c, float(log_ndtr((mu - c) / sd)),
                           f"component {k}, {SIDE_FEATURE} > 0"))
        out.append(Stratum(model, k, e.copy(), c, float(log_ndtr((c - mu) / sd)),
                           f"component {k}, {SIDE_FEATURE} < 0"))
    return out


def halfspace_strata(model: CutInGMM, a: FloatArray, b: float, source: str = "") -> list[Stratum]:
    """One stratum per component with positive weight, each restricted to the half-space
    ``{a.z <= b}`` (a region's envelope, ``sampler.methods.envelope``: the region lies inside it).
    Their masses sum to P(S), not 1: ``P(A) = sum_s pi_s P_s(A)`` still holds for any A
    inside S, and each ``P_s(A)`` is a conditional probability given S, far less rare than
    P(A) when S is tight (``ttc<3``: P(S) = 2e-3)."""

    model.check_fitted()
    a = np.asarray(a, dtype=np.float64)
    _, _, log_pk = component_projections(model, a, float(b))
    where = f"{source} envelope" if source else "envelope"
    return [Stratum(model, k, a.copy(), float(b), float(log_pk[k]), f"component {k}, {where}")
            for k in range(model.n_components_) if model.weights_[k] > 0]
