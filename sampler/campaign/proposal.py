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
from scipy.special import logsumexp

from sampler.methods.envelope import HalfSpace, find_envelope
from sampler.methods.importance import KernelProposal
from sampler.model.bootstrap import pooled_model
from sampler.model.gmm import CutInGMM
from sampler.model.memo import memoised
from sampler.region.constraints import Region

__all__ = ["DEFAULT_ENVELOPES", "MixturePart", "Proposal", "build_proposal", "widened_model"]

FloatArray = NDArray[np.float64]

#: critical half-spaces the proposal keeps a share on (a constraint each)
DEFAULT_ENVELOPES: tuple[str, ...] = ("ttc<1.5", "ttc<3", "gap<4", "p_a1<-2", "dv>4")


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


def _envelope_parts(model: CutInGMM, constraints: Sequence[str], lane_width: float,
                    region: Region | None) -> list[_EnvelopePart]:
    out: list[_EnvelopePart] = []
    seen: set[tuple[float, ...]] = set()
    todo: list[tuple[str, Region]] = []
    if region is not None and region.constraints:
        todo.append(("region", region))
    for c in constraints:
        todo.append((c, Region.from_constraints([c], lane_width=lane_width)))
    for name, reg in todo:
        def find(r: Region = reg) -> HalfSpace | None:
            return find_envelope(model, r)

        hs = memoised(model, ("campaign_envelope", reg), find)
        if hs is None:
            continue
        key = (*np.round(hs.a, 12).tolist(), round(hs.b, 12))
        if key in seen:
            continue
        seen.add(key)
        out.append(_EnvelopePart(f"envelope:{name if name != 'region' else hs.source}",
                                 model, hs))
    return out


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
