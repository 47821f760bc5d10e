"""A proposal part that lives exactly on a band set: ``lo(z_rest) < z_j < hi(z_rest)``.

The slow-cutter set ``0 < v_cut_min < c`` is such a set. The cutter's lowest speed is
``p_v0 + delta`` with ``delta = min(-p_a1 c0, p_a1 (p_a3 - c0))`` and
``c0 = clip(-p_a2, 0, p_a3)`` (``sampler.region.kinematics.plateau_speeds``): given the
other parameters it is the initial speed plus a constant, so the set is an interval of
``p_v0``, ``-delta < p_v0 < c - delta``, and an interval of its z coordinate (the
feature transforms are monotone). In z-space the set is a thin curved band (about 0.6
standard deviations wide where braking cutters live), which no mixture of normals or t
laws follows; its mass is a few 1e-4 of the model.

``BandPart`` draws the other coordinates ``z_rest`` from a density ``g`` (a Student-t
mixture over d - 1 coordinates), then ``z_j`` from the model's own conditional law
``p(z_j | z_rest)`` truncated to the band::

    q(z) = g(z_rest) p(z_j | z_rest) 1[lo < z_j < hi] / F(z_rest),
    F(z_rest) = P_p(lo < z_j < hi | z_rest)

``p(z_j | z_rest)`` of a normal mixture is a normal mixture in closed form (component
responsibilities from the marginal of ``z_rest``; each component's conditional mean and
variance by the Schur complement), and so is ``F`` (differences of normal CDFs). The
density is exact and normalised for any ``g``; its weight against the model is
``p / q = p(z_rest) F(z_rest) / g(z_rest)``: the thin direction is followed exactly and
only the smooth ``p(z_rest) F(z_rest)`` is left for ``g`` to fit. Where the band is empty
(``F = 0``: no initial speed gives a slow cutter), ``z_j`` is drawn from the untruncated
conditional instead, so q stays a density on every ``z_rest``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr, logsumexp, ndtri

from sampler.model.gmm import CutInGMM
from sampler.region.kinematics import plateau_speeds

__all__ = ["BandPart", "ConditionalLaw", "RestDensity", "RestFit", "band_part_for_set",
           "v_cut_min_band"]

FloatArray = NDArray[np.float64]
#: (n, d) z rows (the band coordinate ignored) -> (lo, hi) of the band coordinate
BandFn = Callable[[FloatArray], tuple[FloatArray, FloatArray]]


def _log_diff_ndtr(a: FloatArray, b: FloatArray) -> FloatArray:
    """``log(Phi(b) - Phi(a))`` for ``a <= b``, accurate in both tails (-inf if equal)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    # on the upper side use the mirror: Phi(b) - Phi(a) = Phi(-a) - Phi(-b)
    up = a > 0
    hi = np.where(up, -a, b)
    lo = np.where(up, -b, a)
    lh, ll = log_ndtr(hi), log_ndtr(lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = lh + np.log1p(-np.exp(ll - lh))
    return np.asarray(np.where(b > a, out, -np.inf), dtype=np.float64)


@dataclass
class ConditionalLaw:
    """The model's law of coordinate ``j`` given the others (a normal mixture)."""

    model: CutInGMM
    j: int
    _rest: NDArray[np.int64] = field(init=False, repr=False)
    #: (n,) log marginal density of ``z_rest`` at the rows of the last ``components`` call
    last_log_marginal: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        d = int(self.model.n_features)
        self._rest = np.array([i for i in range(d) if i != self.j], dtype=np.int64)
        r, j = self._rest, self.j
        means = np.asarray(self.model.means_, dtype=np.float64)
        covs = np.asarray(self.model.covariances_, dtype=np.float64)
        tr = self.model.transforms_[self.j]
        if tr.kind not in ("identity", "log", "log_shift") or not tr.scale > 0:
            raise ValueError(f"band coordinate {self.j}: needs an increasing transform, "
                             f"got {tr.kind}")
        self.last_log_marginal = np.zeros(0)
        self.log_w = np.log(np.asarray(self.model.weights_, dtype=np.float64))
        self.mu_r = means[:, r]
        self.mu_j = means[:, j]
        self.chol_rr: list[FloatArray] = []
        self.beta: list[FloatArray] = []
        self.sd: list[float] = []
        for k in range(means.shape[0]):
            s_rr = covs[k][np.ix_(r, r)]
            s_rj = covs[k][r, j]
            beta = np.linalg.solve(s_rr, s_rj)
            self.chol_rr.append(np.linalg.cholesky(s_rr))
            self.beta.append(beta)
            self.sd.append(math.sqrt(float(covs[k][j, j] - s_rj @ beta)))

    @property
    def rest(self) -> NDArray[np.int64]:
        return self._rest

    def components(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(K, n) log-responsibilities of the components given ``z_rest`` (normalised),
        conditional means and standard deviations of ``z_j``; also the (n,) log marginal
        density of ``z_rest`` as ``self.last_log_marginal``."""
        zr = z[:, self._rest]
        k = self.mu_r.shape[0]
        lr = np.empty((k, z.shape[0]))
        m = np.empty((k, z.shape[0]))
        s = np.empty((k, z.shape[0]))
        d = zr.shape[1]
        for c in range(k):
            y = np.linalg.solve(self.chol_rr[c], (zr - self.mu_r[c]).T)
            lr[c] = (self.log_w[c] - 0.5 * (y * y).sum(axis=0)
                     - np.log(np.diag(self.chol_rr[c])).sum() - 0.5 * d * math.log(2 * math.pi))
            m[c] = self.mu_j[c] + (zr - self.mu_r[c]) @ self.beta[c]
            s[c] = self.sd[c]
        tot = logsumexp(lr, axis=0)
        self.last_log_marginal = np.asarray(tot, dtype=np.float64)
        return lr - tot[None, :], m, s

    def log_mass(self, z: FloatArray, lo: FloatArray, hi: FloatArray,
                 comps: tuple[FloatArray, FloatArray, FloatArray] | None = None
                 ) -> tuple[FloatArray, FloatArray]:
        """(n,) ``log F`` = log P(lo < z_j < hi | z_rest) and the (K, n) log terms
        (``comps``: ``components(z)`` when the caller has them already)."""
        lr, m, s = self.components(z) if comps is None else comps
        terms = lr + _log_diff_ndtr((lo[None, :] - m) / s, (hi[None, :] - m) / s)
        return np.asarray(logsumexp(terms, axis=0), dtype=np.float64), terms

    def log_pdf_j(self, z: FloatArray,
                  comps: tuple[FloatArray, FloatArray, FloatArray] | None = None
                  ) -> FloatArray:
        """(n,) log p(z_j | z_rest) (``comps`` as in ``log_mass``)."""
        lr, m, s = self.components(z) if comps is None else comps
        x = (z[:, self.j][None, :] - m) / s
        return np.asarray(logsumexp(lr - 0.5 * x * x - np.log(s)
                                    - 0.5 * math.log(2 * math.pi), axis=0), dtype=np.float64)


class RestDensity(Protocol):
    """A normalised density over ``z_rest`` (the d - 1 other coordinates, in order)."""

    def log_q(self, z: FloatArray) -> FloatArray: ...

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray: ...


@dataclass
class BandPart:
    """``q(z) = g(z_rest) p(z_j | z_rest) 1_band / F`` (module docstring). ``g`` has
    ``log_q(zr)`` and ``draw(n, rng)`` over the d - 1 other coordinates in order."""

    name: str
    law: ConditionalLaw
    band: BandFn
    g: RestDensity

    def _bounds(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        lo, hi = self.band(z)
        lo = np.where(np.isnan(lo), -np.inf, lo)
        hi = np.where(np.isnan(hi), -np.inf, hi)
        return lo, np.maximum(hi, lo)

    def log_q(self, z: FloatArray) -> FloatArray:
        z = np.asarray(z, dtype=np.float64)
        lo, hi = self._bounds(z)
        comps = self.law.components(z)
        log_f, _ = self.law.log_mass(z, lo, hi, comps)
        log_cond = self.law.log_pdf_j(z, comps)
        zj = z[:, self.law.j]
        inside = (zj >= lo) & (zj <= hi)
        empty = ~np.isfinite(log_f)
        lg = np.asarray(self.g.log_q(z[:, self.law.rest]), dtype=np.float64)
        with np.errstate(invalid="ignore"):
            on_band = np.where(inside, log_cond - log_f, -np.inf)
        return np.asarray(lg + np.where(empty, log_cond, on_band), dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        law = self.law
        zr = np.asarray(self.g.draw(n, rng), dtype=np.float64)
        z = np.zeros((n, zr.shape[1] + 1))
        z[:, law.rest] = zr
        lo, hi = self._bounds(z)
        comps = law.components(z)
        log_f, terms = law.log_mass(z, lo, hi, comps)
        lr, m, s = comps
        empty = ~np.isfinite(log_f)
        # the component: by its share of the band's mass (or of the whole law if empty)
        logits = np.where(empty[None, :], lr, terms - np.where(empty, 0.0, log_f)[None, :])
        cdf = np.cumsum(np.exp(logits - logsumexp(logits, axis=0)[None, :]), axis=0)
        u = rng.random(n)
        comp = np.minimum((u[None, :] > cdf).sum(axis=0), cdf.shape[0] - 1)
        cols = np.arange(n)
        mk, sk = m[comp, cols], s[comp, cols]
        a = np.where(empty, -np.inf, (lo - mk) / sk)
        b = np.where(empty, np.inf, (hi - mk) / sk)
        zj = mk + sk * _truncated_std_normal(a, b, rng.random(n))
        # m + s ((hi - m) / s) can round past hi: keep the draw on its band
        z[:, law.j] = np.where(empty, zj, np.clip(zj, lo, hi))
        return z


def _truncated_std_normal(a: FloatArray, b: FloatArray, u: FloatArray) -> FloatArray:
    """Inverse-CDF draws of N(0, 1) truncated to (a, b) from uniforms ``u``; the upper
    tail by the mirror so that deep tails keep their precision."""
    up = a > 0
    lo = np.where(up, -b, a)
    hi = np.where(up, -a, b)
    la, lb = log_ndtr(lo), log_ndtr(hi)
    # Phi(lo) + u (Phi(hi) - Phi(lo)) in log space
    with np.errstate(divide="ignore", invalid="ignore"):
        lp = np.logaddexp(la + np.log1p(-u), lb + np.log(u))
    x = np.clip(ndtri(np.exp(lp)), lo, hi)
    # a band beyond ~37 standard deviations underflows: its finite end stands in (the
    # density is still evaluated exactly at the point drawn)
    x = np.where(np.isfinite(x), x, np.where(np.isfinite(hi), hi, lo))
    return np.asarray(np.where(up, -x, x), dtype=np.float64)


def v_cut_min_band(model: CutInGMM, c: float) -> BandFn:
    """The band of the set ``0 < v_cut_min < c`` in ``p_v0``'s z coordinate given the
    other coordinates (module docstring); -inf bounds where no speed qualifies."""
    feats = list(model.features_)
    j = feats.index("p_v0")
    tr = model.transforms_[j]
    ia1, ia2, ia3 = feats.index("p_a1"), feats.index("p_a2"), feats.index("p_a3")

    def band(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        x = model.from_z(z)
        a1, a2, a3 = x[:, ia1], x[:, ia2], x[:, ia3]
        before, after = plateau_speeds(a1, a2, a3, np.zeros_like(a1))
        delta = np.minimum(before, after)  # the lowest speed minus p_v0
        with np.errstate(invalid="ignore", divide="ignore"):
            lo = np.asarray(tr.forward(np.maximum(-delta, 0.0))[0], dtype=np.float64)
            hi = np.asarray(tr.forward(c - delta)[0], dtype=np.float64)
        lo = np.where(np.isnan(lo) | (-delta <= 0), -np.inf, lo)
        hi = np.where(np.isnan(hi) | (c - delta <= 0), -np.inf, hi)
        return lo, hi

    return band


#: the most model draws ``g`` is fitted to (``band_part_for_set``)
MAX_FIT_ROWS = 20_000
#: fits ``g``: (z_rest rows, their weights, generator) -> a density over z_rest
RestFit = Callable[[FloatArray, FloatArray, np.random.Generator], RestDensity]


def band_part_for_set(model: CutInGMM, c: float, fit: RestFit, *, seed: int = 0,
                      n: int = 1 << 18, name: str | None = None) -> BandPart | None:
    """The band part of ``0 < v_cut_min < c`` with ``g = fit(...)`` fitted to the set's
    law of the other coordinates, ``p(z_rest) F(z_rest) / P``: ``n`` model draws
    (``default_rng(seed)``: deterministic) weighted by their ``F`` (no draw is thrown
    away). None when fewer than 2 d effective rows carry weight."""
    j = list(model.features_).index("p_v0")
    law = ConditionalLaw(model, j)
    band = v_cut_min_band(model, c)
    rng = np.random.default_rng(seed)
    z = np.asarray(model.sample_z(n, rng), dtype=np.float64)
    lo, hi = band(z)
    log_f, _ = law.log_mass(z, np.where(np.isnan(lo), -np.inf, lo),
                            np.maximum(np.where(np.isnan(hi), -np.inf, hi), lo))
    f = np.exp(log_f - np.max(log_f))
    ess = float(f.sum() ** 2 / (f * f).sum())
    d = z.shape[1]
    if not np.isfinite(ess) or ess < 2 * d:
        return None
    # the rows that carry the weight: F above 1e-6 of its largest, at most MAX_FIT_ROWS of
    # them (the largest F; the fit's cost grows with the rows, their weight does not)
    keep = np.flatnonzero(f > 1e-6)
    if keep.size > MAX_FIT_ROWS:
        keep = keep[np.argsort(-f[keep], kind="stable")[:MAX_FIT_ROWS]]
        keep.sort()
    g = fit(z[keep][:, law.rest], f[keep], rng)
    return BandPart(name or f"band:v_cut_min<{c:g}", law, band, g)
