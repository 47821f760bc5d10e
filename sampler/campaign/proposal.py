"""The campaign's importance density: a defensive mixture in the model's z-space.

``q(z) = sum_j s_j q_j(z)`` with fixed shares ``s_j`` (summing to 1) over parts that each
have an exact, normalised density:

* ``model`` — the model ``p`` itself (share ``alpha``). Since ``q >= alpha p``, every
  weight ``p / q`` is at most ``1 / alpha`` (defensive importance sampling, Hesterberg
  1995, Technometrics 37(2));
* ``wide`` — a wider law over the same space: the average of the model's bootstrap
  replicates (``sampler.model.pooled_model``) when the model has them, else the model with
  every covariance times ``widen^2``. With the replicates' average as a part, the weight of
  replicate b against q, ``p_b / q``, is at most ``B / s_wide``: the model interval
  (reweighting the same runs under each replicate) cannot blow up;
* ``envelope:<constraint>`` — the model restricted to a critical half-space S
  (``sampler.methods.envelope``: ``ttc < c``, ``gap < g``, ``p_a1 < a``, ...), density
  ``p(z) 1_S(z) / P(S)`` with the exact mass ``P(S)`` (a sum of normal CDFs);
* ``fitted`` — after collisions were seen: an equal mixture of multivariate Student-t
  kernels centred at collided runs resampled by their weights, scale the weighted
  covariance of the collided runs times Silverman's factor (the kernels' normaliser is the
  t density's own, exact). A non-parametric cross-entropy step: the collided runs,
  weighted, are draws of the zero-variance density ``p 1_C / P(C)`` (Rubinstein & Kroese
  2004, The Cross-Entropy Method; kernel form as ``sampler.methods.importance``).

A draw picks each row's part by its share, then draws that part; the weight of a row uses
the whole mixture's density (not the part's): unbiased whatever the shares.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.special import logsumexp

from sampler.campaign.band import BandPart, band_part_for_set, fit_band_part, lateral_band
from sampler.methods.envelope import HalfSpace, find_envelope
from sampler.methods.importance import KernelProposal
from sampler.model.bootstrap import pooled_model
from sampler.model.gmm import CutInGMM
from sampler.model.memo import memoised
from sampler.region.constraints import Region

__all__ = ["BAND_STEP_ENVELOPES", "DEFAULT_ENVELOPES", "BandPool", "GaussianMixture",
           "MixturePart", "Proposal", "band_part", "build_ce_proposal", "build_proposal",
           "campaign_envelopes", "fit_ce_mixture", "fit_weighted_gmm", "lateral_band_parts",
           "region_mixture", "tune_shares", "widened_model"]

FloatArray = NDArray[np.float64]

#: critical sets the proposal keeps a share on (a constraint each): a half-space
#: envelope where ``find_envelope`` has one, else a mixture fitted to the model's draws
#: inside the set (``v_cut_min<3``: a cutter that slows to a crawl or a stop; its speed
#: is a product of the pulse's acceleration and length, no half-space in z)
DEFAULT_ENVELOPES: tuple[str, ...] = ("ttc<1.5", "ttc<3", "gap<4", "p_a1<-2", "dv>4",
                                      "v_cut_min<3", "end_margin<0.03")

#: the critical sets of a campaign with ``band_step``: the default ones with the slow
#: cutter's set narrowed to ``v_cut_min<1.5``, which holds most of its collisions in
#: less than half the model's mass (docs/evaluation.md, "Measured again")
BAND_STEP_ENVELOPES: tuple[str, ...] = tuple("v_cut_min<1.5" if e == "v_cut_min<3" else e
                                             for e in DEFAULT_ENVELOPES)


def campaign_envelopes(envelopes: Sequence[str], band_step: bool) -> tuple[str, ...]:
    """The critical sets a campaign draws from: ``BAND_STEP_ENVELOPES`` for the default
    list with ``band_step``, else ``envelopes`` as given (a list of your own is kept)."""
    env = tuple(envelopes)
    return BAND_STEP_ENVELOPES if band_step and env == DEFAULT_ENVELOPES else env

#: the cross-entropy stage's share of the parts fitted to a set without a half-space
SET_SHARE = 0.2
#: ... and in the final stage (level 0), once the band parts' own collisions are fitted
FINAL_SET_SHARE = 0.1
#: the final stage's share of the band parts refitted to the runs on their bands (split
#: equally between the bands that have such runs)
BAND_HITS_SHARE = 0.2
#: the final stage's share of the Student-t kernels at the collided runs
FINAL_KERNEL_SHARE = 0.2
#: the final stage's shares with ``evaluate(..., band_step=True)``: the set and band
#: parts, the band refits (the bands' own cross-entropy step included) and the kernels
BAND_STEP_SET_SHARE = 0.2
BAND_STEP_HITS_SHARE = 0.3
BAND_STEP_KERNEL_SHARE = 0.1
#: the refit's weights are ``(p / q)^BAND_HITS_TEMPER``, its scales times ``BAND_HITS_INFLATE``
BAND_HITS_TEMPER = 1.0
BAND_HITS_INFLATE = 1.6
BAND_HITS_K = 2
#: the final stage's share of each band part whose ``g`` is Student-t kernels at the
#: collided runs on its band (taken from the refit's ``BAND_HITS_SHARE``)
BAND_KERNEL_SHARE = 0.1
#: most kernel centres of that part, their bandwidth factor and degrees of freedom
BAND_KERNEL_CENTRES = 300
BAND_KERNEL_INFLATE = 1.3
#: a band with too few collided runs: its own cross-entropy step on this many of its
#: lowest-score runs, once the band part drew ``BAND_LEVEL_MIN_DRAWN`` rows
BAND_LEVEL_ELITE = 30
BAND_LEVEL_MIN_DRAWN = 150


class MixturePart(Protocol):
    name: str

    def log_q(self, z: FloatArray) -> FloatArray: ...

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray: ...


@dataclass
class _ModelPart:
    name: str
    model: CutInGMM

    def log_q(self, z: FloatArray) -> FloatArray:
        return np.asarray(self.model.log_density_z(z), dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        return np.asarray(self.model.sample_z(n, rng), dtype=np.float64)


@dataclass
class _EnvelopePart:
    name: str
    model: CutInGMM
    half_space: HalfSpace

    def log_q(self, z: FloatArray) -> FloatArray:
        return np.asarray(self.half_space.log_q(self.model, z), dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        return np.asarray(self.half_space.sample_z(self.model, n, rng), dtype=np.float64)


@dataclass
class _KernelPart:
    name: str
    kernels: KernelProposal

    def log_q(self, z: FloatArray) -> FloatArray:
        return np.asarray(self.kernels.log_g(z), dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        return np.asarray(self.kernels.draw_g(n, rng), dtype=np.float64)


class Proposal:
    """``q = sum_j s_j q_j`` (module docstring); ``describe()`` lists parts and shares."""

    def __init__(self, parts: Sequence[MixturePart], shares: Sequence[float]) -> None:
        s = np.asarray(shares, dtype=np.float64)
        if len(parts) != s.size or not parts or not (s > 0).all():
            raise ValueError("proposal: one positive share per part")
        self.parts = list(parts)
        self.shares = s / s.sum()
        #: the cross-entropy mixture fitted for this proposal (``build_ce_proposal``)
        self.fitted: GaussianMixture | None = None
        self._log_s = np.log(self.shares)

    def log_q(self, z: FloatArray) -> FloatArray:
        terms = np.stack([ls + part.log_q(z) for ls, part in zip(self._log_s, self.parts,
                                                                  strict=True)])
        return np.asarray(logsumexp(terms, axis=0), dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> tuple[FloatArray, NDArray[np.int64]]:
        """``n`` rows of q in z-space and the part each came from (rows in draw order)."""
        cdf = np.cumsum(self.shares)
        cdf[-1] = 1.0
        labels = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"),
                            len(self.parts) - 1).astype(np.int64)
        z: FloatArray | None = None
        for j, part in enumerate(self.parts):
            idx = np.flatnonzero(labels == j)
            if not idx.size:
                continue
            zj = part.draw(int(idx.size), rng)
            if z is None:
                z = np.full((n, zj.shape[1]), np.nan)
            z[idx] = zj
        assert z is not None
        return z, labels

    def describe(self) -> list[dict[str, Any]]:
        return [{"part": p.name, "share": float(s)} for p, s in zip(self.parts, self.shares,
                                                                      strict=True)]


def widened_model(model: CutInGMM, widen: float = 1.5) -> CutInGMM:
    """The model with every covariance times ``widen^2`` (same weights, means, transforms)."""
    data = model.to_dict()
    data["bootstrap"] = None
    out = CutInGMM.from_dict(data)
    out.set_mixture(np.asarray(model.weights_, dtype=np.float64),
                    np.asarray(model.means_, dtype=np.float64),
                    np.asarray(model.covariances_, dtype=np.float64) * widen * widen)
    return out


def _wide_part(model: CutInGMM, widen: float) -> _ModelPart:
    if getattr(model, "bootstrap_", None):
        wide = memoised(model, ("campaign_pooled",), lambda: pooled_model(model))
        return _ModelPart("wide:bootstrap-average", wide)
    wide = memoised(model, ("campaign_widened", float(widen)),
                    lambda: widened_model(model, widen))
    return _ModelPart(f"wide:x{widen:g}", wide)


def region_mixture(model: CutInGMM, region: Region, *, seed: int = 0, block: int = 1 << 18,
                   max_blocks: int = 32, min_rows: int = 400, max_k: int = 3,
                   inflate: float = 1.2, nu: float = 5.0) -> GaussianMixture | None:
    """A Student-t mixture in z-space fitted to the model's draws inside ``region`` (for
    a set with no half-space envelope). Model draws in blocks of ``block`` (from
    ``default_rng(seed)``: deterministic) until ``min_rows`` fall inside or
    ``max_blocks`` were drawn (or none fell inside the first block); ``fit_ce_mixture``
    on them (equal weights, fitted covariances times ``inflate^2``, ``nu`` degrees of
    freedom). None with fewer than
    2 (d + 1) rows inside. The mixture's density is its own, exact: as a proposal part
    it keeps the estimate unbiased however well it fits the set."""
    reg = region.bind(model)
    rng = np.random.default_rng(seed)
    rows: list[FloatArray] = []
    n_in = 0
    for _ in range(max_blocks):
        z = np.asarray(model.sample_z(block, rng), dtype=np.float64)
        z_in = z[np.asarray(reg.contains(model.params_matrix(model.from_z(z))), dtype=bool)]
        rows.append(z_in)
        n_in += z_in.shape[0]
        if n_in >= min_rows or n_in == 0:  # none in the first block: too rare to fit
            break
    d = rows[0].shape[1]
    if n_in < 2 * (d + 1):
        return None
    z_all = np.concatenate(rows)
    return fit_ce_mixture(z_all, np.ones(n_in), rng, max_k=max_k, inflate=inflate, nu=nu,
                          shape="fitted")


def _envelope_parts(model: CutInGMM, constraints: Sequence[str], lane_width: float,
                    region: Region | None) -> list[MixturePart]:
    out: list[MixturePart] = []
    seen: set[tuple[float, ...]] = set()
    todo: list[tuple[str, Region]] = []
    if region is not None and region.constraints:
        todo.append(("region", region))
    for c in constraints:
        todo.append((c, Region.from_constraints([c], lane_width=lane_width)))
    for name, reg in todo:
        lat_c = _end_margin_bound(reg) if name != "region" else None
        if lat_c is not None:
            # a thin band of p_y1 on each side (sampler.campaign.band.lateral_band), drawn
            # by band parts directly: no half-space envelope is searched for
            def make_lateral(c: float = lat_c, nm: str = name,
                             lw: float = reg.lane_width) -> tuple[BandPart, ...]:
                return tuple(lateral_band_parts(model, c, lw, name=f"band:{nm}"))

            out.extend(memoised(model, ("campaign_lateral_band", reg), make_lateral))
            continue

        def find(r: Region = reg) -> HalfSpace | None:
            return find_envelope(model, r)

        hs = memoised(model, ("campaign_envelope", reg), find)
        if hs is None:
            if name == "region":
                continue
            band_c = _v_cut_min_bound(reg)
            if band_c is not None:
                def make_band(c: float = band_c, nm: str = name) -> BandPart | None:
                    return band_part(model, c, name=f"band:{nm}")

                bp = memoised(model, ("campaign_band", reg), make_band)
                if bp is not None:
                    out.append(bp)
                    continue

            def fit(r: Region = reg) -> GaussianMixture | None:
                return region_mixture(model, r)

            gm = memoised(model, ("campaign_region_mixture", reg), fit)
            if gm is not None:
                out.append(_MixturePart(f"set:{name}", gm))
            continue
        key = (*np.round(hs.a, 12).tolist(), round(hs.b, 12))
        if key in seen:
            continue
        seen.add(key)
        out.append(_EnvelopePart(f"envelope:{name if name != 'region' else hs.source}",
                                 model, hs))
    return out


def band_part(model: CutInGMM, c: float, *, seed: int = 0, n: int = 1 << 18,
              name: str | None = None) -> BandPart | None:
    """The band part of ``0 < v_cut_min < c`` (``sampler.campaign.band``), its ``g`` a
    Student-t(5) mixture (K <= 3 by BIC, fitted covariances times 1.2^2) fitted to
    ``n`` model draws weighted by the band's conditional mass."""
    return band_part_for_set(model, c, _rest_fit, seed=seed, n=n, name=name)


def _rest_fit(zr: FloatArray, w: FloatArray, rng: np.random.Generator) -> GaussianMixture:
    """A band part's ``g``: Student-t(5) mixture, K <= 3 by BIC, covariances times 1.2^2."""
    return fit_ce_mixture(zr, w, rng, max_k=3, inflate=1.2, nu=5.0, shape="fitted")


def lateral_band_parts(model: CutInGMM, c: float, lane_width: float, *, seed: int = 0,
                       n: int = 1 << 18, name: str | None = None) -> list[BandPart]:
    """The band parts of ``0 < end_margin < c`` (a cutter whose lane change ends just
    inside the ego lane): one per side, ``{name}:left`` (``p_y1 > 0``, the cutter moves
    left) and ``{name}:right`` (``p_y1 < 0``), each on ``lateral_band``'s band of
    ``p_y1`` with ``g`` fitted as ``band_part``'s (seeds ``seed`` and ``seed + 1``) to a
    uniform subset of the weighted rows (``fit_band_part(thin="random")``: on the TNO
    model each band holds about a percent of the model); a side whose band carries too
    little of the model's mass is left out."""
    j = list(model.features_).index("p_y1")
    base = name or f"band:end_margin<{c:g}"
    out: list[BandPart] = []
    for k, (side, label) in enumerate(((1, "left"), (-1, "right"))):
        bp = fit_band_part(model, j, lateral_band(model, c, side, lane_width), _rest_fit,
                           f"{base}:{label}", seed=seed + k, n=n, thin="random")
        if bp is not None:
            out.append(bp)
    return out


def _end_margin_bound(region: Region) -> float | None:
    """``c`` when ``region`` is the single constraint ``end_margin < c`` (or ``<=``), c > 0."""
    cons = list(region.constraints)
    if (len(cons) == 1 and cons[0].name == "end_margin" and cons[0].op in ("<", "<=")
            and cons[0].value > 0):
        return float(cons[0].value)
    return None


def _v_cut_min_bound(region: Region) -> float | None:
    """``c`` when ``region`` is the single constraint ``v_cut_min < c`` (or ``<=``)."""
    cons = list(region.constraints)
    if len(cons) == 1 and cons[0].name == "v_cut_min" and cons[0].op in ("<", "<="):
        return float(cons[0].value)
    return None


def _fitted_part(z_hits: FloatArray, w_hits: FloatArray, rng: np.random.Generator,
                 model: CutInGMM, max_centres: int, inflate: float, nu: float
                 ) -> _KernelPart:
    """Student-t kernels at the collided runs resampled by weight (module docstring)."""
    p = w_hits / w_hits.sum()
    m = min(max_centres, max(z_hits.shape[0], 1) * 4)
    idx = rng.choice(z_hits.shape[0], size=m, p=p)
    centres = z_hits[idx]
    d = z_hits.shape[1]
    mean = p @ z_hits
    diff = z_hits - mean
    cov = (diff * p[:, None]).T @ diff
    # a floor from the model's own spread: a few collided runs must not make a needle
    floor = 0.05 * np.eye(d)
    shape_cov = cov + floor
    # KernelProposal takes the shape as sample rows: hand it rows with that covariance
    chol = np.linalg.cholesky(shape_cov)
    basis = np.concatenate([np.eye(d), -np.eye(d)]) * math.sqrt(d)
    shape_rows = basis @ chol.T
    n_distinct = int(np.unique(np.round(z_hits, 12), axis=0).shape[0])
    kern = KernelProposal(model, centres, inflate=inflate, alpha=0.5, nu=nu,
                          shape=shape_rows * math.sqrt((2 * d - 1) / (2 * d)),
                          n_bandwidth=max(n_distinct, 1))
    return _KernelPart(f"fitted:t{nu:g}x{n_distinct}", kern)


def build_proposal(model: CutInGMM, *, region: Region | None, lane_width: float,
                   envelopes: Sequence[str] = DEFAULT_ENVELOPES,
                   hits: tuple[FloatArray, FloatArray] | None = None,
                   rng: np.random.Generator | None = None, alpha: float = 0.15,
                   wide_share: float = 0.15, fitted_share: float = 0.45,
                   widen: float = 1.5, max_centres: int = 300, inflate: float = 1.3,
                   nu: float = 5.0) -> Proposal:
    """The proposal of one chunk: model, wide, the envelopes and (with ``hits``: z rows of
    collided runs and their weights) the fitted kernels.

    Shares: ``alpha`` to the model, ``wide_share`` to the wide part, ``fitted_share`` to
    the fitted kernels when there are hits, the rest evenly to the envelopes (the model and
    wide parts share it when there is no envelope).
    """
    parts: list[MixturePart] = [_ModelPart("model", model), _wide_part(model, widen)]
    shares = [alpha, wide_share]
    env = _envelope_parts(model, envelopes, lane_width, region)
    fitted = None
    if hits is not None and hits[0].shape[0] > 0:
        if rng is None:
            raise ValueError("build_proposal: hits need a Generator")
        fitted = _fitted_part(hits[0], hits[1], rng, model, max_centres, inflate, nu)
    rest = 1.0 - alpha - wide_share - (fitted_share if fitted is not None else 0.0)
    if fitted is not None:
        parts.append(fitted)
        shares.append(fitted_share)
    if env:
        parts.extend(env)
        shares.extend([rest / len(env)] * len(env))
    else:
        shares[0] += rest / 2
        shares[1] += rest / 2
    return Proposal(parts, shares)


# --------------------------------------------------------------------------- cross-entropy

def _mvn_logpdf(z: FloatArray, means: FloatArray, covs: FloatArray) -> FloatArray:
    """(K, n) log-densities of the normals N(means[k], covs[k]) at the rows of z."""
    k, d = means.shape
    out = np.empty((k, z.shape[0]))
    for j in range(k):
        chol = np.linalg.cholesky(covs[j])
        sol = np.linalg.solve(chol, (z - means[j]).T)
        out[j] = (-0.5 * (sol * sol).sum(axis=0) - np.log(np.diag(chol)).sum()
                  - 0.5 * d * math.log(2 * math.pi))
    return out


@dataclass
class GaussianMixture:
    """A mixture in z-space: ``weights`` (K,), ``means`` (K, d), ``covs`` (K, d, d);
    normal components, or multivariate Student-t with ``nu`` degrees of freedom and
    scale matrices ``covs`` when ``nu`` is finite (polynomial tails: the weight ``p / q``
    of a proposal made of them vanishes far out). Exact normalised density."""

    weights: FloatArray
    means: FloatArray
    covs: FloatArray
    nu: float = math.inf

    def log_q(self, z: FloatArray) -> FloatArray:
        z = np.asarray(z, dtype=np.float64)
        if math.isinf(self.nu):
            lp = _mvn_logpdf(z, self.means, self.covs)
        else:
            lp = _mvt_logpdf(z, self.means, self.covs, self.nu)
        return np.asarray(logsumexp(lp + np.log(self.weights)[:, None], axis=0),
                          dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        k, d = self.means.shape
        comp = np.minimum(np.searchsorted(np.cumsum(self.weights), rng.random(n),
                                          side="right"), k - 1)
        eps = rng.standard_normal((n, d))
        if not math.isinf(self.nu):
            eps = eps * np.sqrt(self.nu / rng.chisquare(self.nu, size=n))[:, None]
        out = np.empty((n, d))
        for j in range(k):
            idx = np.flatnonzero(comp == j)
            if idx.size:
                out[idx] = self.means[j] + eps[idx] @ np.linalg.cholesky(self.covs[j]).T
        return out


def _mvt_logpdf(z: FloatArray, means: FloatArray, scales: FloatArray, nu: float
                ) -> FloatArray:
    """(K, n) log-densities of multivariate Student-t(nu) laws at the rows of z."""
    k, d = means.shape
    out = np.empty((k, z.shape[0]))
    const = (math.lgamma((nu + d) / 2) - math.lgamma(nu / 2)
             - 0.5 * d * math.log(nu * math.pi))
    for j in range(k):
        chol = np.linalg.cholesky(scales[j])
        sol = np.linalg.solve(chol, (z - means[j]).T)
        m2 = (sol * sol).sum(axis=0)
        out[j] = const - np.log(np.diag(chol)).sum() - 0.5 * (nu + d) * np.log1p(m2 / nu)
    return out


def fit_weighted_gmm(z: FloatArray, w: FloatArray, k: int, rng: np.random.Generator, *,
                     floor: float = 0.02, iters: int = 60) -> tuple[GaussianMixture, float]:
    """Weighted EM of a K-component normal mixture on rows ``z`` with weights ``w``
    (normalised inside): maximises ``sum_i w_i log q(z_i)``, the cross-entropy step
    (Rubinstein & Kroese 2004, ch. 3; the weights are ``p / q`` of the runs and the rows
    the elite). ``floor`` is added to every covariance's diagonal (no needle on a few
    points). Initial means: K rows drawn by weight without replacement (``rng``), so the
    fit is deterministic given the generator. Returns the mixture and the weighted mean
    log-likelihood."""
    z = np.asarray(z, dtype=np.float64)
    om = np.asarray(w, dtype=np.float64)
    om = om / om.sum()
    m, d = z.shape
    k = max(1, min(int(k), int(np.count_nonzero(om))))
    start = rng.choice(m, size=k, replace=False, p=om)
    means = z[start].copy()
    mu = om @ z
    glob = ((z - mu) * om[:, None]).T @ (z - mu) + floor * np.eye(d)
    covs = np.repeat(glob[None], k, axis=0)
    pis = np.full(k, 1.0 / k)
    ll = -math.inf
    for _ in range(iters):
        lp = _mvn_logpdf(z, means, covs) + np.log(pis)[:, None]
        tot = logsumexp(lp, axis=0)
        new_ll = float(om @ tot)
        r = np.exp(lp - tot[None, :]) * om[None, :]  # (k, m)
        nk = r.sum(axis=1)
        keep = nk > 1e-9
        r, nk = r[keep], nk[keep]
        pis = nk / nk.sum()
        means = (r @ z) / nk[:, None]
        covs = np.empty((nk.size, d, d))
        for j in range(nk.size):
            diff = z - means[j]
            covs[j] = (diff * r[j][:, None]).T @ diff / nk[j] + floor * np.eye(d)
        if abs(new_ll - ll) < 1e-8:
            ll = new_ll
            break
        ll = new_ll
    return GaussianMixture(pis, means, covs), ll


def fit_ce_mixture(z: FloatArray, w: FloatArray, rng: np.random.Generator, *,
                   max_k: int = 3, floor: float = 0.02, inflate: float = 1.2,
                   nu: float = 5.0, model: CutInGMM | None = None,
                   min_share: float = 0.1, shape: str = "model") -> GaussianMixture:
    """The cross-entropy density of elite rows ``z`` weighted by ``w``: K in 1..max_k
    by BIC with Kish's effective size ``(sum w)^2 / sum w^2`` as the sample size (a K
    is tried only with at least 2 (d + 1) effective rows per component); the proposal's
    components are then Student-t(``nu``) at the fitted means with the fitted
    covariances times ``inflate^2`` as scales (``nu = inf``: the normals themselves).
    A normal fitted to a failure set that is cut by a plane is narrower than the model
    across the plane, so its weights ``p / q`` grow without bound deep in the set; the
    t's heavier tails keep them bounded there.

    With ``model``: half of the mixture's weight goes to one more component per model
    component k, fitted to the elite weighted by ``w`` times the model's responsibility
    of k (share: the weighted fraction of the elite under k, at least ``min_share``
    before renormalising). A failure set that cuts several of the model's components
    keeps a component on each even when the EM above, led by a few heavy weights,
    merged them (the cross-entropy method's known way of missing a mode).

    ``shape="model"`` (with ``model``; the default): each component keeps its fitted
    mean but takes the model's own covariance there (the model's covariances averaged
    by their responsibilities at that mean) times ``inflate^2``: a mean shift. For a
    failure set cut by a plane the weight ``p / q`` of a shifted normal with the model's
    covariance is the exponential of a linear function, bounded on the set; a fitted
    (narrower) covariance makes it grow across the set, and the interval undercovers.
    ``shape="fitted"``: the fitted covariances."""
    om = np.asarray(w, dtype=np.float64) / float(np.sum(w))
    ess = 1.0 / float((om * om).sum())
    d = z.shape[1]
    best: tuple[float, GaussianMixture] | None = None
    for k in range(1, max_k + 1):
        if k > 1 and ess < 2 * (d + 1) * k:
            break
        gm, ll = fit_weighted_gmm(z, om, k, rng, floor=floor)
        n_par = (gm.weights.size - 1) + gm.weights.size * (d + d * (d + 1) / 2)
        bic = -2 * ess * ll + n_par * math.log(max(ess, 2.0))
        if best is None or bic < best[0]:
            best = (bic, gm)
    assert best is not None
    gm = best[1]
    weights, means, covs = gm.weights, gm.means, gm.covs
    if model is not None:
        lr = (np.log(np.asarray(model.weights_, dtype=np.float64))[:, None]
              + _mvn_logpdf(z, np.asarray(model.means_, dtype=np.float64),
                            np.asarray(model.covariances_, dtype=np.float64)))
        resp = np.exp(lr - logsumexp(lr, axis=0)[None, :])  # (K_model, m)
        mw, mm, mc = [], [], []
        for rk in resp:
            wk = om * rk
            tot = float(wk.sum())
            if tot <= 1e-12:
                continue
            mu = wk @ z / tot
            diff = z - mu
            mw.append(tot)
            mm.append(mu)
            mc.append((diff * wk[:, None]).T @ diff / tot + floor * np.eye(d))
        if mw:
            share = np.maximum(np.asarray(mw) / sum(mw), min_share)
            share /= share.sum()
            weights = np.concatenate([0.5 * weights, 0.5 * share])
            means = np.concatenate([means, np.asarray(mm)])
            covs = np.concatenate([covs, np.asarray(mc)])
    if model is not None and shape == "model":
        mcov = np.asarray(model.covariances_, dtype=np.float64)
        lr = (np.log(np.asarray(model.weights_, dtype=np.float64))[:, None]
              + _mvn_logpdf(np.asarray(means), np.asarray(model.means_, dtype=np.float64),
                            mcov))
        rm = np.exp(lr - logsumexp(lr, axis=0)[None, :])  # (K_model, K)
        covs = np.einsum("km,kij->mij", rm, mcov)
    return GaussianMixture(weights, means, covs * inflate * inflate, nu=nu)


@dataclass
class _MixturePart:
    name: str
    mixture: GaussianMixture

    def log_q(self, z: FloatArray) -> FloatArray:
        return self.mixture.log_q(z)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        return self.mixture.draw(n, rng)


def build_ce_proposal(model: CutInGMM, *, region: Region | None, lane_width: float,
                      elite: tuple[FloatArray, FloatArray] | None, level: float,
                      rng: np.random.Generator,
                      envelopes: Sequence[str] = DEFAULT_ENVELOPES, alpha: float = 0.1,
                      wide_share: float = 0.05, envelope_share: float = 0.1,
                      kernel_share: float = FINAL_KERNEL_SHARE, widen: float = 1.5, max_k: int = 3,
                      history: Sequence[GaussianMixture] = (), history_share: float = 0.1,
                      inflate: float = 1.2, set_share: float | None = None,
                      band_hits_share: float = BAND_HITS_SHARE,
                      pool: BandPool | None = None, tune: bool = False) -> Proposal:
    """The proposal of one chunk of an adaptive cross-entropy campaign: the model
    (``alpha``: weights stay below ``1 / alpha``), the wide part, the envelopes
    (``envelope_share`` together) and, with ``elite`` (z rows and their weights ``p/q``
    of the runs whose performance score is at most ``level``), a normal mixture fitted
    to them (:func:`fit_ce_mixture`) with the rest. At level 0 (the elite are the
    collided runs) also the Student-t kernels of :func:`build_proposal` on them
    (``kernel_share``): non-parametric, they keep mass on every collided run, so a
    failure family found once (by an envelope, say) is drawn again in the next chunk
    even when the mixture fit has no component there; and for each band part
    (``sampler.campaign.band``) the same band refitted to the collided runs on it
    (``band_hits_share`` each, :func:`_band_hit_parts`; with ``pool``, all the runs so
    far, a band with too few collided runs gets the cross-entropy step on its own
    runs' scores instead). The set and band parts share
    ``set_share``: ``SET_SHARE`` in the pilot, ``FINAL_SET_SHARE`` at level 0 by
    default. Without elite: as :func:`build_proposal` before any collision.

    With ``tune`` at level 0 the shares are then set from the collided runs so far
    (:func:`tune_shares`): the model keeps ``alpha``, every other part stays within
    ``TUNE_LO``-``TUNE_HI`` times the share given above."""
    if set_share is None:
        set_share = SET_SHARE if level > 0 else FINAL_SET_SHARE
    if elite is None or elite[0].shape[0] == 0:
        return build_proposal(model, region=region, lane_width=lane_width,
                              envelopes=envelopes, alpha=0.15)
    parts: list[MixturePart] = [_ModelPart("model", model), _wide_part(model, widen)]
    shares = [alpha, wide_share]
    env_all = _envelope_parts(model, envelopes, lane_width, region)
    env = [e for e in env_all if not e.name.startswith(("set:", "band:"))]
    sets = [e for e in env_all if e.name.startswith(("set:", "band:"))]
    gm = fit_ce_mixture(elite[0], elite[1], rng, max_k=max_k, model=model, inflate=inflate)
    rest = (1.0 - alpha - wide_share - (envelope_share if env else 0.0)
            - (set_share if sets else 0.0))
    if level <= 0:
        parts.append(_fitted_part(elite[0], elite[1], rng, model, 300, 1.3, 5.0))
        shares.append(kernel_share)
        rest -= kernel_share
        for hp, share in _band_hit_parts(sets, elite, rng, band_hits_share, pool):
            parts.append(hp)
            shares.append(share)
            rest -= share
    if history:
        parts.append(_MixturePart(f"ce:levels{len(history)}", _pooled_mixtures(history)))
        shares.append(history_share)
        rest -= history_share
    if rest <= 0:
        raise ValueError(f"build_ce_proposal: the fixed shares (alpha {alpha:g} and the "
                         f"others) leave {rest:.3g} for the fitted mixture; lower alpha")
    parts.append(_MixturePart(f"ce:gmm{gm.weights.size}@{level:.4g}x{elite[0].shape[0]}",
                              gm))
    shares.append(rest)
    if env:
        parts.extend(env)
        shares.extend([envelope_share / len(env)] * len(env))
    if sets:
        parts.extend(sets)
        shares.extend([set_share / len(sets)] * len(sets))
    if tune and level <= 0:
        fixed = np.zeros(len(parts), dtype=bool)
        fixed[0] = True  # the model: the defensive share, weights <= 1 / alpha
        shares = list(tune_shares(parts, np.asarray(shares) / np.sum(shares), elite[0],
                                  elite[1], np.asarray(model.log_density_z(elite[0])),
                                  fixed=fixed))
    out = Proposal(parts, shares)
    out.fitted = gm
    return out


#: bounds of a tuned share, times the part's fixed share (:func:`tune_shares`)
TUNE_LO = 0.5
TUNE_HI = 3.0
#: fewest collided runs to tune on
TUNE_MIN_HITS = 20


def tune_shares(parts: Sequence[MixturePart], shares: FloatArray, z: FloatArray,
                w: FloatArray, log_p: FloatArray, *, fixed: NDArray[np.bool_],
                lo: float = TUNE_LO, hi: float = TUNE_HI) -> FloatArray:
    """Shares of ``parts`` that minimise the estimated second moment of the next
    chunk's weighted collision indicator (He & Owen 2014, "Optimal mixture weights in
    multiple importance sampling", arXiv:1411.3954).

    ``z``, ``w``: the collided runs so far and their weights ``p / q_k`` under the
    proposal ``q_k`` each was drawn from; ``log_p``: the model's log density there.
    For shares ``s``, ``q_s = sum_j s_j q_j`` and ``E_{q_s}[(1_C p / q_s)^2] =
    E_{q_k}[1_C p^2 / (q_k q_s)]``, estimated (up to the constant number of draws) by
    ``F(s) = sum_i w_i p_i / q_s(z_i)``: convex in ``s``, minimised over the simplex
    with the ``fixed`` parts at their shares and every other part ``j`` within
    ``[lo s_j, hi s_j]`` (SLSQP). The bounds keep every part drawing: a collision
    family no run has met yet keeps the shares that might meet it, and parts fitted to
    these very runs, whose density there is optimistic, cannot take everything.
    Returns ``shares`` unchanged with fewer than ``TUNE_MIN_HITS`` runs. Deterministic.
    The estimate stays unbiased: the shares depend on earlier chunks only."""
    s0 = np.asarray(shares, dtype=np.float64)
    s0 = s0 / s0.sum()
    free = ~np.asarray(fixed, dtype=bool)
    if z.shape[0] < TUNE_MIN_HITS or not free.any():
        return s0
    with np.errstate(divide="ignore"):
        logr = np.stack([np.asarray(part.log_q(z), dtype=np.float64) for part in parts],
                        axis=1) - np.asarray(log_p, dtype=np.float64)[:, None]
    logr = np.where(np.isfinite(logr), logr, -np.inf)
    m = logr.max(axis=1)
    ok = np.isfinite(m) & (w > 0)
    if int(ok.sum()) < TUNE_MIN_HITS:
        return s0
    r = np.exp(logr[ok] - m[ok, None])           # rows scaled to max 1
    c = w[ok] * np.exp(-m[ok])                    # F = sum_i c_i / (r_i . s)
    c = c / c.sum()
    budget = 1.0 - float(s0[~free].sum())
    base = r[:, ~free] @ s0[~free]
    rf = r[:, free]

    def f(x: FloatArray) -> tuple[float, FloatArray]:
        q = base + rf @ x
        v = c / q
        return float(v.sum()), -(rf.T @ (v / q))

    x0 = s0[free]
    bounds = [(lo * v, min(hi * v, budget)) for v in x0]
    res = minimize(f, x0, jac=True, method="SLSQP", bounds=bounds,
                   constraints=[{"type": "eq", "fun": lambda x: float(x.sum()) - budget,
                                 "jac": lambda x: np.ones_like(x)}],
                   options={"maxiter": 200, "ftol": 1e-12})
    x = np.clip(np.asarray(res.x, dtype=np.float64), [b[0] for b in bounds],
                [b[1] for b in bounds])
    if not (np.all(np.isfinite(x)) and f(x)[0] <= f(x0)[0]):
        return s0
    out = s0.copy()
    out[free] = x * budget / x.sum()
    return out


@dataclass
class BandPool:
    """All the simulated runs so far, for the bands' own cross-entropy step: z rows,
    weights ``p / q``, performance scores (at most 0 exactly for the collided runs) and,
    per part name, how many rows that part drew."""

    z: FloatArray
    w: FloatArray
    score: FloatArray
    drawn: dict[str, int]


def _band_level_elite(b: BandPart, pool: BandPool, min_drawn: int, size: int,
                      block: int = 4096) -> tuple[FloatArray, FloatArray] | None:
    """The ``size`` runs on ``b``'s band with the lowest scores (z rows, weights), once
    the band part drew at least ``min_drawn`` rows (so the elite is the band's lower
    tail, at most ``size / min_drawn`` of its runs); None before, or with fewer runs
    on the band. Walks the runs by ascending score in blocks (the band is evaluated on
    the rows it needs only)."""
    if pool.drawn.get(b.name, 0) < min_drawn:
        return None
    order = np.argsort(pool.score, kind="stable")
    order = order[np.isfinite(pool.score[order])]
    got: list[NDArray[np.int64]] = []
    n_got = 0
    for i in range(0, order.size, block):
        idx = order[i:i + block]
        lo, hi = b.band(pool.z[idx])
        zj = pool.z[idx, b.law.j]
        on = idx[(zj >= lo) & (zj <= hi)]
        got.append(on[:size - n_got])
        n_got += min(on.size, size - n_got)
        if n_got >= size:
            break
    if n_got < size:
        return None
    sel = np.concatenate(got)
    return pool.z[sel], pool.w[sel]


def _band_hit_parts(sets: Sequence[MixturePart], elite: tuple[FloatArray, FloatArray],
                    rng: np.random.Generator, share: float = BAND_HITS_SHARE,
                    pool: BandPool | None = None) -> list[tuple[BandPart, float]]:
    """For each band part, when at least 2 d collided runs lie on its band, two parts of
    the same band with their shares (together ``share``, split equally between the bands
    that have such runs): ``g`` refitted to those runs
    (weighted by ``p / q``, at most ``BAND_HITS_K`` components: the cross-entropy step
    inside the band) and ``g`` made of Student-t kernels at them (resampled by weight,
    ``BAND_KERNEL_SHARE``: non-parametric, so a group of collided runs on the band that
    the refit does not cover, found once by the band part itself, is drawn again). The
    band's thin direction is still drawn exactly from the model's conditional law
    (``sampler.campaign.band``).

    With ``pool`` (all the runs so far), a band with fewer collided runs gets one part,
    ``ce:<band>-level``, its ``g`` refitted the same way to the ``BAND_LEVEL_ELITE``
    runs on the band with the lowest scores, once the band part drew
    ``BAND_LEVEL_MIN_DRAWN`` rows (:func:`_band_level_elite`): a multi-level
    cross-entropy step inside the band, led by the band's own near misses. A collision
    family that is a small corner of its band (the drifting cutter of ``end_margin``)
    is too rare under the band part for the campaign to meet 2 d of it; its near misses
    lead the band there."""
    z, w = elite
    out: list[tuple[BandPart, float]] = []
    eligible: list[tuple[BandPart, FloatArray, FloatArray, bool]] = []
    for b in sets:
        if not isinstance(b, BandPart):
            continue
        lo, hi = b.band(z)
        zj = z[:, b.law.j]
        on = (zj >= lo) & (zj <= hi)
        if int(on.sum()) >= 2 * z.shape[1]:
            eligible.append((b, z[on][:, b.law.rest], w[on], True))
            continue
        lev = None if pool is None else _band_level_elite(
            b, pool, BAND_LEVEL_MIN_DRAWN, max(BAND_LEVEL_ELITE, 2 * z.shape[1]))
        if lev is not None:
            eligible.append((b, lev[0][:, b.law.rest], lev[1], False))
    # several bands with such runs split ``share`` equally (one band keeps all of it)
    n_b = max(len(eligible), 1)
    k_share = min(BAND_KERNEL_SHARE, share) / n_b
    b_share = share / n_b
    for b, zr, wr, hits in eligible:
        g = fit_ce_mixture(zr, wr ** BAND_HITS_TEMPER, rng, max_k=BAND_HITS_K,
                           inflate=BAND_HITS_INFLATE, nu=5.0, shape="fitted")
        if not hits:
            out.append((BandPart(f"ce:{b.name}-level", b.law, b.band, g), b_share))
            continue
        if k_share < b_share:
            out.append((BandPart(f"ce:{b.name}-hits", b.law, b.band, g), b_share - k_share))
        if k_share > 0:
            out.append((BandPart(f"ce:{b.name}-kernels", b.law, b.band,
                                 band_kernels(zr, wr, rng)), k_share))
    return out


def band_kernels(z: FloatArray, w: FloatArray, rng: np.random.Generator, *,
                 max_centres: int | None = None, inflate: float | None = None,
                 nu: float = 5.0) -> GaussianMixture:
    """Student-t kernels at rows ``z`` resampled by weight ``w`` (at most ``max_centres``
    centres, equal shares), one scale for all: the rows' weighted covariance plus a floor
    of 0.05 per coordinate, times the square of Silverman's factor
    ``(4 / (d + 2))^(1 / (d + 4)) n^(-1 / (d + 4))`` (``n``: the distinct rows) and of
    ``inflate``: the rule of ``KernelProposal`` over the rows' own space."""
    max_centres = BAND_KERNEL_CENTRES if max_centres is None else max_centres
    inflate = BAND_KERNEL_INFLATE if inflate is None else inflate
    p = np.asarray(w, dtype=np.float64) / float(np.sum(w))
    m = min(max_centres, max(z.shape[0], 1) * 4)
    centres = z[rng.choice(z.shape[0], size=m, p=p)]
    d = z.shape[1]
    diff = z - p @ z
    cov = (diff * p[:, None]).T @ diff + 0.05 * np.eye(d)
    n_distinct = max(int(np.unique(np.round(z, 12), axis=0).shape[0]), 1)
    h = (4.0 / (d + 2)) ** (1.0 / (d + 4)) * n_distinct ** (-1.0 / (d + 4)) * inflate
    return GaussianMixture(np.full(m, 1.0 / m), centres,
                           np.broadcast_to(h * h * cov, (m, d, d)).copy(), nu=nu)


def _pooled_mixtures(mixtures: Sequence[GaussianMixture]) -> GaussianMixture:
    """The equal-share mixture of several mixtures of the same ``nu`` (one mixture)."""
    nus = {m.nu for m in mixtures}
    if len(nus) != 1:
        raise ValueError("pooled mixtures: one nu for all")
    n = len(mixtures)
    return GaussianMixture(np.concatenate([m.weights / n for m in mixtures]),
                           np.concatenate([m.means for m in mixtures]),
                           np.concatenate([m.covs for m in mixtures]), nu=nus.pop())
