"""Subset simulation followed by importance sampling (``subset-is``) for rare regions.

Plain subset simulation (``sampler.subset``) cannot be much cheaper than naive Monte Carlo
for the same CoV: with ``p0 = 0.1``, ``L`` levels of ``N`` points and no chain correlation
its squared CoV is at least ``L (1 - p0) / (N p0)`` for ``L N`` evaluations, an
acceleration of at most ``p0 / (P L^2 (1 - p0))`` (about 70 at 1e-4, 440 at 1e-5). Here
the subset levels only *find* the region; P(A) then comes from importance sampling with a
defensive kernel density (Hesterberg 1995; kernel densities from Markov-chain samples in
the failure region: Au & Beck 1999, Structural Safety 21)

    q = (1 - alpha) g + alpha p,        P(A) = mean_i 1_A(z_i) p(z_i) / q(z_i),  z_i ~ q,

``p`` the model (its share ``alpha`` bounds the weights by ``1 / alpha``), ``g`` an equal
mixture of Gaussians centred at points inside A with the covariance of those points times
Silverman's bandwidth factor squared times ``inflate**2``:

1. subset simulation with ``n_per_level`` points per level; its final level's samples
   inside A are the first centres;
2. adaptation (``adapt_rounds``, default 1): ``n_adapt`` draws of that q; those inside A,
   resampled by their weights (so they follow the model restricted to A rather than the
   subset chains' coverage of it), are the centres of the next q;
3. ``n_is`` draws of the final q give the estimate and its CoV (sample standard error /
   estimate). Only this stage's draws enter the estimate (its proposal is fixed given the
   earlier stages, so the estimate is unbiased); every limit-state evaluation of all
   three stages is counted in ``n_evaluations``.

With g close to the model restricted to A the per-draw squared CoV is about
``alpha / (1 - alpha)`` whatever P(A) is; measured figures are in ``docs/sampler.md``.

Samples of the model restricted to A come from independence Metropolis-Hastings chains
(Liu 1996, "Metropolized independent sampling") whose proposals are the final stage's
draws themselves (i.i.d. from q): a proposal ``z'`` replaces the state ``z`` with
probability ``min(1, w(z') / w(z))``, ``w = 1_A p / q``. Exact for its stationary law,
no new evaluations, honest diagnostics: acceptance, integrated autocorrelation time
(``sampler.mcmc._tau``), effective sample size. More draws of q are made (and enter P(A)
too) until the chains' effective sample size reaches ``ess_target * n``, within the time
budget.

``subset_importance(model, limit_state, seed)`` is the estimator as a function (any
vectorised z-space limit state, ``sampler.subset.region_limit_state`` for a region);
``rare_probability(model, constraints, seed)`` the same for constraints;
``SubsetISSampler`` (name ``subset-is``) the sampler.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sampler._exceptions import EmptyRegionError, SamplerError
from sampler.importance import ImportanceStage, KernelProposal, independence_chain, kish_ess
from sampler.mcmc import _tau
from sampler.model import CutInGMM
from sampler.problem import Draw, FloatArray, Pilot, Problem, ProgressFn, Sampler
from sampler.subset import LimitState, SubsetResult, region_limit_state, subset_simulation

__all__ = ["RareResult", "SubsetISSampler", "rare_probability", "subset_importance"]


@dataclass(frozen=True)
class RareResult:
    """Outcome of ``subset_importance``.

    Attributes
    ----------
    probability : float
        Importance-sampling estimate of ``P(g <= 0)`` under the model.
    cov : float
        Its coefficient of variation (sample standard error / estimate). ``cov_upper`` is
        the same figure (the interface ``sampler.probability`` reads).
    n_evaluations : int
        Every limit-state evaluation: the subset stage's plus the importance draws.
    n_subset_evaluations, n_adapt, n_is, n_hits : int
        The subset stage's evaluations, the adaptation's draws, the final importance
        draws, and those of them inside A.
    ess_weights : float
        Kish's effective sample size of the weights of the final draws inside A.
    z, log_w : ndarray
        The importance draws inside A (z-space) and their ``log p - log q``, in draw order.
    subset : SubsetResult
        The stage that found the region (its own estimate included).
    proposal : dict
        What q was (centres, alpha, inflation).
    """

    probability: float
    cov: float
    n_evaluations: int
    n_subset_evaluations: int
    n_adapt: int
    n_is: int
    n_hits: int
    ess_weights: float
    z: FloatArray = field(repr=False)
    log_w: FloatArray = field(repr=False)
    subset: SubsetResult = field(repr=False)
    proposal: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    method: str = "subset-is"

    @property
    def cov_upper(self) -> float:
        return self.cov

    def summary(self) -> dict[str, Any]:
        """JSON-able figures (without the samples)."""
        return {"probability": self.probability, "cov": self.cov,
                "n_evaluations": self.n_evaluations,
                "n_subset_evaluations": self.n_subset_evaluations,
                "n_adapt": self.n_adapt, "n_is": self.n_is,
                "n_hits": self.n_hits, "hit_rate": self.n_hits / max(self.n_is, 1),
                "ess_weights": self.ess_weights, "proposal": self.proposal,
                "seconds": self.seconds, "subset": self.subset.summary()}


def subset_importance(model: CutInGMM, limit_state: LimitState, seed: int, *,
                      n_per_level: int = 1000, n_is: int = 4000, alpha: float = 0.1,
                      inflate: float = 1.3, p0: float = 0.1,
                      n_adapt: int = 1500, adapt_rounds: int = 2, n_centres: int = 300,
                      nu: float = 5.0,
                      max_seconds: float = 120.0, min_probability: float = 1e-14,
                      keep_stage: list[ImportanceStage] | None = None) -> RareResult:
    """Estimate ``P(limit_state(z) <= 0)`` under the model: subset levels, then importance
    sampling from a defensive kernel density (module docstring).

    Parameters
    ----------
    n_per_level : int
        Points per subset level (the stage that finds the region).
    n_is : int
        Importance draws of the final proposal (the estimate).
    alpha : float
        The model's share of the proposal, in (0, 1).
    inflate : float
        Scale of the kernels' standard deviations (on Silverman's bandwidth).
    n_adapt, adapt_rounds : int
        Draws per adaptation round, and rounds.
    n_centres : int
        Centres resampled after each adaptation round (distinct ones are kept).
    max_seconds, min_probability : float
        Time budget of the whole run; the subset stage gives up below this mass.
    keep_stage : list, optional
        If given, the importance stage is appended to it (to draw more later).

    Raises
    ------
    SamplerError
        Bad settings, or the time budget was spent (how far it got is in the message).
    EmptyRegionError
        The subset levels did not reach the region (see ``subset_simulation``).
    """
    if not 0.0 < alpha < 1.0:
        raise SamplerError(f"alpha: must be in (0, 1), got {alpha!r}")
    if n_is < 2 or n_adapt < 2 or not inflate > 0 or adapt_rounds < 0 or n_centres < 2:
        raise SamplerError("n_is and n_adapt must be >= 2, inflate > 0, adapt_rounds >= 0, "
                           "n_centres >= 2")
    t0 = time.monotonic()
    deadline = t0 + float(max_seconds)
    sub = subset_simulation(model, limit_state, seed, n_per_level=n_per_level, p0=p0,
                            max_seconds=max_seconds, min_probability=min_probability)
    pts = np.unique(sub.z, axis=0)
    d = model.n_features
    if pts.shape[0] < d + 2:
        raise EmptyRegionError(
            f"subset-is: the final subset level holds {pts.shape[0]} distinct points inside "
            "the region, too few to fit an importance density; raise n_per_level",
            n_draws=sub.n_evaluations, n_hits=int(pts.shape[0]), p_upper=sub.probability)
    rng = np.random.default_rng([int(seed) % (2**32), 1])
    proposal = KernelProposal(model, pts, inflate, alpha, nu)
    n_adapt_evals = 0
    for _ in range(adapt_rounds):
        # importance draws inside A resampled by their weights (they follow the model
        # restricted to A, not the subset chains' coverage of it) are the next centres
        pilot = ImportanceStage(model, limit_state, proposal, deadline, max_seconds)
        pilot.add(int(n_adapt), rng)
        n_adapt_evals += pilot.n
        lw = pilot.log_w
        ok = np.isfinite(lw)
        if ok.sum() > d + 1:
            zi, lwi = pilot.z[ok], lw[ok]
            ww = np.exp(lwi - lwi.max())
            pick = rng.choice(zi.shape[0], size=min(n_centres, zi.shape[0]),
                              p=ww / ww.sum())
            proposal = KernelProposal(model, zi[np.unique(pick)], inflate, alpha, nu,
                                      shape=zi[pick])
    stage = ImportanceStage(model, limit_state, proposal, deadline, max_seconds)
    stage.add(int(n_is), rng)
    if keep_stage is not None:
        keep_stage.append(stage)
    return _result(stage, sub, t0, n_adapt_evals, inflate)


def _result(stage: ImportanceStage, sub: SubsetResult, t0: float, n_adapt: int,
            inflate: float) -> RareResult:
    p, cov = stage.estimate()
    lw = stage.log_w
    inside = np.isfinite(lw)
    if not inside.any():
        raise EmptyRegionError(
            f"subset-is: none of {stage.n} importance draws fell inside the region although "
            "the subset levels reached it; raise n_is", n_draws=sub.n_evaluations + stage.n,
            n_hits=0, p_upper=sub.probability)
    prop = stage.proposal
    return RareResult(
        probability=p, cov=cov, n_evaluations=sub.n_evaluations + n_adapt + stage.n,
        n_subset_evaluations=sub.n_evaluations, n_adapt=n_adapt, n_is=stage.n,
        n_hits=int(inside.sum()),
        ess_weights=kish_ess(lw[inside]), z=stage.z[inside], log_w=lw[inside], subset=sub,
        proposal={"kind": "defensive-kernel-density", "centres": prop.k,
                  "alpha": prop.alpha, "inflate": inflate,
                  "centres_from": ("importance draws inside A resampled by weight"
                                   if n_adapt else "final subset level")},
        seconds=time.monotonic() - t0)


class SubsetISSampler(Sampler):
    """Subset levels, importance sampling for P(A), an independence chain for the samples.

    Parameters
    ----------
    n_per_level, n_is, alpha, inflate, n_adapt, adapt_rounds, n_centres :
        See ``subset_importance``.
    max_seconds : float
        Time budget of the whole run; exceeded -> ``SamplerError``.
    min_probability : float
        Give up (``EmptyRegionError``) when the subset levels get below this mass.
    ess_target : float
        Draw more proposals until the chains' effective sample size is at least
        ``ess_target * n`` (when the budget is nearly spent first: a warning in the
        diagnostics instead).
    n_chains : int
        Independence chains the proposals are dealt to.
    """

    name = "subset-is"

    def __init__(self, n_per_level: int = 1000, n_is: int = 4000, alpha: float = 0.1,
                 inflate: float = 1.3, n_adapt: int = 1500, adapt_rounds: int = 2,
                 n_centres: int = 300, max_seconds: float = 120.0,
                 min_probability: float = 1e-14, ess_target: float = 0.25,
                 n_chains: int = 4) -> None:
        self.n_per_level = int(n_per_level)
        self.n_is = int(n_is)
        self.alpha = float(alpha)
        self.inflate = float(inflate)
        self.n_adapt = int(n_adapt)
        self.adapt_rounds = int(adapt_rounds)
        self.n_centres = int(n_centres)
        self.max_seconds = float(max_seconds)
        self.min_probability = float(min_probability)
        self.ess_target = float(ess_target)
        self.n_chains = int(n_chains)

    def _limit_state(self, problem: Problem, rng: np.random.Generator) -> LimitState:
        limit_state = region_limit_state(problem.model, problem.region, rng)

        def counted(z: FloatArray) -> FloatArray:
            problem.n_evals += z.shape[0]
            return limit_state(z)

        return counted

    def run(self, problem: Problem, rng: np.random.Generator,
            keep_stage: list[ImportanceStage] | None = None) -> RareResult:
        """P(A) of the problem's region (also used without samples)."""
        limit_state = self._limit_state(problem, rng)
        seed = int(rng.integers(0, 2**31 - 1))
        return subset_importance(problem.model, limit_state, seed,
                                 n_per_level=self.n_per_level, n_is=self.n_is,
                                 alpha=self.alpha, inflate=self.inflate,
                                 n_adapt=self.n_adapt, adapt_rounds=self.adapt_rounds,
                                 n_centres=self.n_centres, max_seconds=self.max_seconds,
                                 min_probability=self.min_probability, keep_stage=keep_stage)

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        t_start = time.monotonic()
        stages: list[ImportanceStage] = []
        res = self.run(problem, rng, keep_stage=stages)
        stage = stages[0]
        warnings: list[str] = []
        while True:
            states, acc = independence_chain(stage.log_w, rng, self.n_chains)
            zs = stage.z
            tau = _tau(zs[states])  # chain (steps, chains, d)
            tau_max = float(tau.max())
            burn = min(math.ceil(2 * tau_max), states.shape[0] // 2)
            post = states[burn:]
            ess = post.size / tau_max
            if progress is not None:
                progress("subset-is", min(int(ess), n), n)
            if ess >= self.ess_target * n:
                break
            if time.monotonic() - t_start > 0.8 * self.max_seconds:
                warnings.append(f"time budget nearly spent with ESS {ess:.0f} < "
                                f"{self.ess_target * n:.0f}: the samples are more correlated "
                                "than asked")
                break
            need = self.ess_target * n / max(ess, 1.0) * stage.n - stage.n
            stage.add(int(min(max(need * 1.2, 2000), 8 * stage.n)), rng)
        flat = post.reshape(-1)  # time-major: consecutive entries are different chains
        pick = flat[np.linspace(0, flat.size - 1, n).round().astype(int)]
        z = zs[pick]
        res = _result(stage, res.subset, t_start, res.n_adapt, self.inflate)
        diag = {"subset_is": res.summary(), "n_evaluations": problem.n_evals,
                "acceptance_fraction": acc.tolist(), "acceptance_mean": float(acc.mean()),
                "tau": tau.tolist(), "tau_max": tau_max, "burn_in": burn,
                "n_steps": int(states.shape[0]), "n_chains": self.n_chains,
                "ess": float(min(n, ess)), "ess_chain": float(ess),
                "n_distinct": int(np.unique(pick).size), "warnings": warnings}
        return Draw(z=np.ascontiguousarray(z), method=self.name, diagnostics=diag,
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits, subset=res)


def rare_probability(model: CutInGMM, constraints: Any, seed: int, *,
                     lane_width: float | None = None, physical_bounds: bool = True,
                     **settings: Any) -> RareResult:
    """P(A and B) of a region (constraints as for ``sample``) by subset-is, as a function
    (e.g. once per bootstrap replicate of the model). ``settings`` go to
    ``SubsetISSampler``. Divide by P(B) (``sampler.probability``) for P(A); or use
    ``estimate_p_region``, which does both (and picks subset-is for rare regions)."""
    from sampler.constraints import Region

    region = constraints if isinstance(constraints, Region) else Region.from_constraints(
        constraints, lane_width=model.lane_width_ if lane_width is None else lane_width,
        physical_bounds=physical_bounds)
    problem = Problem(model, region, use_envelope=False)
    return SubsetISSampler(**settings).run(problem, np.random.default_rng(seed))
