"""The "model" interval of P(A): the bootstrap replicates' P(A) and their interval (the
module docstring of :mod:`sampler.model.bootstrap` says how and why).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from sampler.errors import EmptyRegionError, LevelsNotConvergedError, ModelError
from sampler.methods.probability import PRegionEstimator
from sampler.methods.problem import Problem
from sampler.methods.rare import rare_probability
from sampler.methods.subset import SubsetSampler
from sampler.model.bootstrap import (
    _mixture_logpdf,
    log_density_z_boot,
    pooled_model,
    replicate_model,
)

__all__ = ["INTERVALS", "bootstrap_ci", "pooled_interval"]

FloatArray = NDArray[np.float64]


def _replicate_settings(subset: Any) -> dict[str, Any]:
    """``SubsetISSampler`` settings of the per-replicate runs: plain (unstratified) unless
    ``subset`` says otherwise. Measured on ``btn > 0.7`` with the TNO model: stratified runs
    left the lower end unresolved (2.8e-13, 51 replicates, 55 s), plain ones resolve it
    (docs/sampler.md)."""

    given = {} if subset is None or isinstance(subset, SubsetSampler) else dict(subset)
    return {"stratify": "never", **given}


def _per_replicate(model: Any, region: Any, seed: int, which: Any,
                   settings: Mapping[str, Any] | None) -> dict[int, tuple[float, float]]:
    """P_b(A and B) of replicates ``which`` each by its own subset-is run
    (``sampler.methods.rare.rare_probability``): ``{b: (P_b(A and B), Kish ESS)}``; a replicate
    whose levels do not reach the region above ``min_probability`` gets 0.0 and ESS inf
    (resolved as "below min_probability")."""

    children = np.random.SeedSequence([int(seed), 12]).spawn(len(model.bootstrap_["weights"]))
    out = {}
    for b in which:
        try:
            rr = rare_probability(replicate_model(model, int(b)), region,
                                  int(children[b].generate_state(1)[0]), **(settings or {}))
            out[int(b)] = (float(rr.probability), float(rr.ess_weights))
        except EmptyRegionError:
            out[int(b)] = (0.0, math.inf)
        except LevelsNotConvergedError:  # no estimate and no bound: an unresolved replicate
            out[int(b)] = (0.0, 0.0)
    return out


def _weights(model: Any, z: FloatArray) -> FloatArray:
    """w_b(z) = p_b(z) / q(z), shape (B, n), q the replicates' average (so w_b <= B)."""
    lp = log_density_z_boot(model, z)
    lq = logsumexp(lp, axis=0) - math.log(lp.shape[0])
    return np.asarray(np.exp(lp - lq), dtype=np.float64)


INTERVALS = ("bc", "percentile", "log-basic", "log-normal")


def bootstrap_ci(replicates: Any, estimate: float, method: str = "bc",
                 confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided bootstrap interval of P(A) from the replicates' estimates and the fitted
    model's own ``estimate``.

    * ``percentile``: the replicates' a/2 and 1 - a/2 quantiles;
    * ``bc``: bias-corrected percentile (Efron 1981; Efron & Tibshirani 1993, ch. 14.3):
      ``z0 = Phi^-1(share of replicates below the estimate, ties half)``, the quantiles
      at ``Phi(2 z0 + z_{a/2})`` and ``Phi(2 z0 + z_{1-a/2})`` (z0 = 0: percentile);
    * ``log-basic``: the basic (reverse percentile) interval on log P,
      ``exp(2 log P - log q_{1-a/2})`` ... ``exp(2 log P - log q_{a/2})``;
    * ``log-normal``: ``log P`` minus the replicates' bias ± z_{1-a/2} times their SD on
      log P.
    Non-finite replicates are left out; replicates <= 0 count as below everything (log
    methods: left out)."""
    from scipy.stats import norm

    if method not in INTERVALS:
        raise ModelError(f"interval: expected one of {', '.join(INTERVALS)}, got {method!r}")
    if not 0.0 < confidence < 1.0:
        raise ModelError(f"confidence: expected 0 < c < 1, got {confidence!r}")
    r = np.asarray(replicates, dtype=np.float64)
    r = r[np.isfinite(r)]
    a = 1.0 - confidence
    if not r.size:
        return math.nan, math.nan
    if method == "percentile":
        lo, hi = np.quantile(r, [a / 2, 1 - a / 2])
        return float(lo), float(hi)
    if not (math.isfinite(estimate) and estimate > 0):
        return math.nan, math.nan
    if method == "bc":
        n = r.size
        share = (np.sum(r < estimate) + 0.5 * np.sum(r == estimate)) / n
        # the share is resolved to 1/n: keep z0 finite (at most the normal quantile of
        # half a replicate from either end)
        z0 = float(norm.ppf(min(max(share, 0.5 / n), 1 - 0.5 / n)))
        z = float(norm.ppf(1 - a / 2))
        levels = norm.cdf([2 * z0 - z, 2 * z0 + z])
        lo, hi = np.quantile(r, levels)
        return float(lo), float(hi)
    lr = np.log(r[r > 0])
    if not lr.size:
        return math.nan, math.nan
    le = math.log(estimate)
    if method == "log-basic":
        q_lo, q_hi = np.quantile(lr, [a / 2, 1 - a / 2])
        return float(math.exp(2 * le - q_hi)), float(math.exp(2 * le - q_lo))
    centre = 2 * le - float(np.mean(lr))
    half = float(norm.ppf(1 - a / 2)) * float(np.std(lr, ddof=1)) if lr.size > 1 else 0.0
    return float(math.exp(centre - half)), float(math.exp(centre + half))


def _fitted_weights(model: Any, z: FloatArray) -> FloatArray:
    """p(z) / q(z) of the fitted mixture p against the replicates' average q, shape (n,)."""
    lp = log_density_z_boot(model, z)
    lq = logsumexp(lp, axis=0) - math.log(lp.shape[0])
    l0 = _mixture_logpdf(z, np.asarray(model.weights_, dtype=np.float64),
                         np.asarray(model.means_, dtype=np.float64),
                         np.asarray(model.covariances_, dtype=np.float64))
    return np.asarray(np.exp(l0 - lq), dtype=np.float64)


def _pooled_stage(model: Any, region: Any, rng: np.random.Generator, rare: bool,
                  n_samples: int, n_plain: int, subset: Any) -> dict[str, Any]:
    """Importance sampling from the replicates' average restricted to the region: per
    replicate P_b(A and B), P_b(B), the effective sample sizes."""

    pooled = pooled_model(model)
    z: FloatArray
    # P_b(A and B) = sum_i v_i w_b(z_i) / n_draws over the draws z_i inside the region,
    # v_i = q(z_i) / (the density z_i was drawn from) times the proposal's mass
    if isinstance(subset, SubsetSampler):
        # plain subset simulation of q (the first version; measured biased low on
        # btn > 0.7: its Markov chains missed the replicates whose tail lies elsewhere)
        problem = Problem(pooled, region)
        res = subset.run(problem, 200, rng)
        z = res.z[region.contains(problem.params(res.z))] if res.z.size else res.z
        v = np.full(z.shape[0], float(res.probability) / max(z.shape[0], 1))
        how = f"subset simulation, {res.n_evaluations} evaluations"
    elif rare:

        rr = rare_probability(pooled, region, int(rng.integers(0, 2**31 - 1)),
                              **(subset or {}))
        z = rr.z
        v = np.exp(rr.log_w) / rr.n_is
        how = (f"subset-is, {rr.n_evaluations} evaluations, {rr.n_hits} of {rr.n_is} "
               "importance draws inside")
    else:
        problem = Problem(pooled, region)
        est = PRegionEstimator(pilot_hits=int(n_samples))
        pilot = est.pilot(problem, rng, need=1)
        z = pilot.hits
        v = np.full(z.shape[0], problem.proposal_mass / max(pilot.n_draws, 1))
        how = f"{pilot.n_draws} plain draws" + (
            "" if problem.envelope is None else " restricted to the envelope")
    if z.shape[0] == 0:
        raise ModelError("model interval: no sample of the pooled replicates inside the region")
    w = _weights(model, z) * v                                   # (B, n)
    w0 = _fitted_weights(model, z) * v                           # (n,)
    s1, s2 = w.sum(axis=1), (w * w).sum(axis=1)
    zp = pooled.sample_z(int(n_plain), rng)
    in_b = region.in_bounds(pooled.params_matrix(pooled.from_z(zp)))
    return {"joint": s1, "joint_q": float(v.sum()), "n": int(z.shape[0]),
            "bounds": (_weights(model, zp) * in_b).mean(axis=1),
            "fitted_joint": float(w0.sum()),
            "fitted_bounds": float((_fitted_weights(model, zp) * in_b).mean()),
            "ess": np.where(s2 > 0, s1 * s1 / np.where(s2 > 0, s2, 1.0), 0.0), "how": how}


def pooled_interval(model: Any, region: Any, seed: int, *, rare: bool,
                    n_samples: int = 2000, n_plain: int = 8192, confidence: float = 0.95,
                    min_ess: float = 10.0, subset: Any = None,
                    interval: str = "percentile",
                    per_replicate: bool = False) -> dict[str, Any]:
    """The "model" interval of P(A) = P(A and B) / P(B) from samples of the replicates'
    average restricted to the region (module docstring).

    Parameters
    ----------
    region : sampler.region.constraints.Region (A and, when on, the physical bounds B)
    rare : subset-is (``sampler.methods.rare.rare_probability``) on the average for its draws in
        the region (regions the plain pilot does not reach, e.g. the simulated
        criticality); else plain (envelope) draws, ``n_samples`` of them inside the region
    min_ess : replicates with fewer effective samples (Kish, of the importance weights)
        are "not resolved"; an end of the interval is resolved when the replicates beyond
        it (the tail share) are
    subset : keyword arguments of ``sampler.methods.rare.SubsetISSampler`` for the rare path, or a
        ``sampler.methods.subset.SubsetSampler`` for the former plain subset simulation of the
        average (measured biased low on ``btn > 0.7``; kept for comparison)
    interval : ``bootstrap_ci`` method; "percentile" (default: the best measured coverage,
        docs/sampler.md), "bc", "log-basic", "log-normal"
    per_replicate : rare path only: every replicate left unresolved by the pooled draws
        gets its own subset-is run (about 0.5 s each on the TNO model for ``btn > 0.7``;
        one whose levels stay above ``min_probability`` = 1e-14 counts as 0)

    Returns also ``fitted``: the fitted model's P(A) from the same draws (what ``bc``
    compares the replicates with), ``n_per_replicate``: replicates run on their own.
    """

    rng = np.random.default_rng(int(seed))
    n_boot = len(model.bootstrap_["weights"])
    a = 1.0 - confidence
    st = _pooled_stage(model, region, rng, rare, n_samples, n_plain, subset)
    joint_b, pb_b, ess = st["joint"], st["bounds"], st["ess"]
    n_refined = 0
    if per_replicate and rare:
        # the replicates the pooled draws do not resolve, each by its own subset-is run
        redo = np.flatnonzero(ess < min_ess)
        for b, (pj, e) in _per_replicate(model, region, int(seed), redo,
                                         _replicate_settings(subset)).items():
            joint_b[b], ess[b] = pj, e
        n_refined = int(redo.size)
    p_b = np.where(pb_b > 0, joint_b / np.where(pb_b > 0, pb_b, 1.0), np.nan)
    p_b = np.minimum(p_b, 1.0)
    ok = np.isfinite(p_b)
    fb = st["fitted_bounds"]
    fitted = min(st["fitted_joint"] / fb, 1.0) if fb > 0 else math.nan
    lo, hi = bootstrap_ci(p_b, fitted, interval, confidence)
    low = ess < min_ess
    # unresolved replicates are the ones seen by few samples: the low ones. The lower end
    # is resolved when no more of them than the tail share exist; the upper end when
    # none of the replicates at or above it is unresolved
    lower_ok = int(np.sum(low)) <= math.floor(a / 2 * n_boot)
    upper_ok = not bool(np.any(low & ok & (p_b >= hi)))
    out = {"ci": [float(lo), float(hi)], "confidence": confidence,
           "median": float(np.median(p_b[ok])) if ok.any() else math.nan,
           "n_boot": int(p_b.size),
           "cov": float(np.std(p_b[ok]) / np.mean(p_b[ok]))
           if ok.any() and np.mean(p_b[ok]) > 0 else math.nan,
           "replicates": [float(v) for v in p_b],
           "fitted": float(fitted), "interval": interval,
           "method": "bootstrap refits; importance sampling from the replicates' average "
                     f"restricted to the region ({st['how']})",
           "n_samples": st["n"], "n_per_replicate": n_refined,
           "ess": {"min": float(ess.min()), "median": float(np.median(ess)),
                   "below_min": int(np.sum(low)), "min_ess": float(min_ess)},
           "lower_resolved": bool(lower_ok), "upper_resolved": upper_ok}
    if not lower_ok:
        out["note"] = (f"{int(np.sum(low))} of {n_boot} replicates have an effective sample "
                       f"size below {min_ess:g}: the lower end is not resolved (estimates "
                       "from few effective samples tend to be low: likely too low)")
    return out
