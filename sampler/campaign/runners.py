"""What a campaign runs: the ``Runner`` protocol and stand-in runners with a known answer.

A runner takes parameter vectors (n, 8) in ``PARAM_NAMES`` order and one seed per run
(uint64) and returns the runs' outcomes: an object with (n,) arrays ``collided`` (bool) and
``impact_speed`` (m/s, 0 without contact), and when it has them ``must_avoid``,
``violation``, margins and ``vs_careful`` (``riskcore.sut.RunBatch`` is one; every (n,)
array attribute is kept per run). :func:`sut_runner` (``sampler.campaign.sut``) drives a
system under test through riskcore's closed-loop simulator; the stand-ins below need no
simulator and have a collision probability known in closed form or by a cheap formula,
for tests and benchmarks:

* :func:`halfspace_runner` — collides iff ``a . z <= b`` in the model's z-space: under the
  model (no physical bounds) its probability is exactly
  ``sum_k w_k Phi((b - a . mu_k) / sqrt(a' Sigma_k a))``;
* :func:`union_runner` — collides iff ``a_j . z <= b_j`` for at least one j of several
  half-spaces (several failure families); under the model its probability is
  :func:`union_probability`, by inclusion-exclusion for two half-spaces (the pair's
  mass is a one-dimensional integral of a normal CDF per model component), exact to
  quadrature precision;
* :func:`late_brake_runner` — a late careful driver: the ego keeps its speed until
  ``reaction`` s after the crossing moment, then brakes at ``decel`` m/s²; the cutter
  keeps its crossing speed. Contact iff ``dv reaction + dv^2 / (2 decel) > gap`` (dv > 0);
  impact speed ``dv`` if contact comes before braking, else
  ``sqrt(dv^2 - 2 decel (gap - dv reaction))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr, logsumexp

from datasets import PARAM_NAMES
from sampler.model.gmm import CutInGMM

__all__ = ["Outcomes", "Runner", "StandInRuns", "halfspace_probability", "halfspace_runner",
           "late_brake_runner", "union_probability", "union_runner"]

FloatArray = NDArray[np.float64]


class Outcomes(Protocol):
    """What a runner returns (``riskcore.sut.RunBatch`` has these and more)."""

    collided: NDArray[np.bool_]
    impact_speed: FloatArray


class Runner(Protocol):
    """``runner(params (n, 8), seeds (n,) uint64) -> Outcomes``; the same inputs give the
    same outcomes, bit for bit."""

    def __call__(self, params: FloatArray, seeds: NDArray[np.uint64]) -> Any: ...


@dataclass
class StandInRuns:
    """Outcomes of a stand-in runner: (n,) arrays."""

    collided: NDArray[np.bool_]
    impact_speed: FloatArray
    must_avoid: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    violation: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: signed distance to the collision set (<= 0 iff collided): the campaign's
    #: continuous performance score (``adapt="ce"``)
    margin: FloatArray = field(default_factory=lambda: np.zeros(0))

    def records(self) -> list[dict[str, Any]]:
        return [{"collided": bool(c), "impact_speed": float(v), "must_avoid": bool(m),
                 "violation": bool(x)}
                for c, v, m, x in zip(self.collided, self.impact_speed, self.must_avoid,
                                      self.violation, strict=True)]


def halfspace_probability(model: CutInGMM, a: FloatArray, b: float) -> float:
    """``P(a . z <= b)`` under the model's mixture in z-space, exact."""
    a = np.asarray(a, dtype=np.float64)
    m = model.means_ @ a
    sd = np.sqrt(np.einsum("i,kij,j->k", a, model.covariances_, a))
    return float(math.exp(logsumexp(np.log(model.weights_) + log_ndtr((b - m) / sd))))


@dataclass(frozen=True)
class _HalfSpaceRunner:
    model: CutInGMM
    a: tuple[float, ...]
    b: float
    name: str = "halfspace"

    def __call__(self, params: FloatArray, seeds: NDArray[np.uint64]) -> StandInRuns:
        x = np.asarray(params, dtype=np.float64)
        feats = [PARAM_NAMES.index(f) for f in self.model.features_]
        z = self.model.to_z(x[:, feats])
        a = np.asarray(self.a)
        margin = (z @ a - self.b) / float(np.linalg.norm(a))
        hit = np.asarray(margin <= 0, dtype=bool)
        dv = x[:, PARAM_NAMES.index("dv")]
        speed = np.where(hit, np.maximum(dv, 0.0), 0.0)
        return StandInRuns(hit, speed, hit.copy(), hit.copy(), margin)


def halfspace_runner(model: CutInGMM, a: FloatArray, b: float) -> _HalfSpaceRunner:
    """A stand-in that collides iff ``a . z <= b`` (z: the model's z-space of the run's
    parameters); its probability under the model is :func:`halfspace_probability`."""
    return _HalfSpaceRunner(model, tuple(float(v) for v in np.asarray(a)), float(b))


def _pair_probability(model: CutInGMM, a1: FloatArray, b1: float, a2: FloatArray,
                      b2: float) -> float:
    """``P(a1 . z <= b1 and a2 . z <= b2)`` under the model's mixture: per component the
    standardised pair (u, v) is bivariate normal with correlation r, and
    ``P(u <= c1, v <= c2) = int_{-inf}^{c1} phi(u) Phi((c2 - r u) / sqrt(1 - r^2)) du``."""
    from scipy.integrate import quad
    from scipy.stats import norm

    total = 0.0
    for w, mu, cov in zip(model.weights_, model.means_, model.covariances_, strict=True):
        s1 = math.sqrt(float(a1 @ cov @ a1))
        s2 = math.sqrt(float(a2 @ cov @ a2))
        r = float(a1 @ cov @ a2) / (s1 * s2)
        c1 = (b1 - float(a1 @ mu)) / s1
        c2 = (b2 - float(a2 @ mu)) / s2
        if abs(r) > 1 - 1e-12:
            raise ValueError("union_probability: parallel half-spaces")
        sr = math.sqrt(1.0 - r * r)
        def f(u: float, c2: float = c2, r: float = r, sr: float = sr) -> float:
            return float(norm.pdf(u) * norm.cdf((c2 - r * u) / sr))

        val, _ = quad(f, -math.inf, c1, epsabs=0.0, epsrel=1e-10, limit=200)
        total += float(w) * val
    return total


def union_probability(model: CutInGMM, half_spaces: list[tuple[FloatArray, float]]) -> float:
    """``P(a_1 . z <= b_1 or a_2 . z <= b_2)`` under the model's mixture (one or two
    half-spaces): ``P(A) + P(B) - P(A and B)``."""
    hs = [(np.asarray(a, dtype=np.float64), float(b)) for a, b in half_spaces]
    if len(hs) == 1:
        return halfspace_probability(model, *hs[0])
    if len(hs) != 2:
        raise ValueError("union_probability: one or two half-spaces")
    (a1, b1), (a2, b2) = hs
    return (halfspace_probability(model, a1, b1) + halfspace_probability(model, a2, b2)
            - _pair_probability(model, a1, b1, a2, b2))


@dataclass(frozen=True)
class _UnionRunner:
    model: CutInGMM
    half_spaces: tuple[tuple[tuple[float, ...], float], ...]
    name: str = "union"

    def __call__(self, params: FloatArray, seeds: NDArray[np.uint64]) -> StandInRuns:
        x = np.asarray(params, dtype=np.float64)
        feats = [PARAM_NAMES.index(f) for f in self.model.features_]
        z = self.model.to_z(x[:, feats])
        margins = [(z @ np.asarray(a) - b) / float(np.linalg.norm(a))
                   for a, b in self.half_spaces]
        margin = np.min(np.stack(margins), axis=0)
        hit = np.asarray(margin <= 0, dtype=bool)
        dv = x[:, PARAM_NAMES.index("dv")]
        speed = np.where(hit, np.maximum(dv, 0.0), 0.0)
        return StandInRuns(hit, speed, hit.copy(), hit.copy(), margin)


def union_runner(model: CutInGMM, half_spaces: list[tuple[FloatArray, float]]
                 ) -> _UnionRunner:
    """A stand-in with several failure families: collides iff the run's z lies in at
    least one of the half-spaces ``a . z <= b``; margin: the smallest signed distance to
    them. Its probability under the model: :func:`union_probability` (two half-spaces)."""
    hs = tuple((tuple(float(v) for v in np.asarray(a)), float(b)) for a, b in half_spaces)
    if not hs:
        raise ValueError("union_runner: at least one half-space")
    return _UnionRunner(model, hs)


@dataclass(frozen=True)
class _LateBrakeRunner:
    reaction: float
    decel: float
    name: str = "late_brake"

    def __call__(self, params: FloatArray, seeds: NDArray[np.uint64]) -> StandInRuns:
        x = np.asarray(params, dtype=np.float64)
        dv = x[:, PARAM_NAMES.index("dv")]
        gap = x[:, PARAM_NAMES.index("gap")]
        closing = dv > 0
        before = closing & (dv * self.reaction >= gap)
        rest = gap - dv * self.reaction
        sq = dv * dv - 2.0 * self.decel * rest
        during = closing & ~before & (sq > 0)
        hit = before | during
        speed = np.where(before, dv, np.where(during, np.sqrt(np.maximum(sq, 0.0)), 0.0))
        # the regulation's verdict stand-in: avoidable if braking at once would avoid it
        must = closing & (dv * dv / (2.0 * self.decel) < gap)
        margin = np.where(closing, gap - dv * self.reaction - dv * dv / (2.0 * self.decel),
                          gap)
        margin = np.where(hit, np.minimum(margin, 0.0), np.where(margin <= 0, 1e-12, margin))
        return StandInRuns(hit, speed, must, must & hit, margin)


def late_brake_runner(reaction: float = 1.2, decel: float = 4.0) -> _LateBrakeRunner:
    """A late careful driver (module docstring): reaction in s after the crossing moment,
    constant deceleration in m/s². ``must_avoid`` here: braking at the crossing moment
    itself would avoid contact (a stand-in for the regulation's formula)."""
    if not (reaction >= 0 and decel > 0):
        raise ValueError("late_brake_runner: reaction >= 0 s and decel > 0 m/s^2")
    return _LateBrakeRunner(float(reaction), float(decel))
