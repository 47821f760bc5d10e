"""Subset simulation followed by importance sampling (``subset-is``) for rare regions.

Plain subset simulation (``sampler.methods.subset``) cannot be much cheaper than naive Monte Carlo
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
2. adaptation (``adapt_rounds``, default 2): ``n_adapt`` draws of that q; those inside A,
   resampled by their weights (so they follow the model restricted to A rather than the
   subset chains' coverage of it), are the centres of the next q;
3. ``n_is`` draws of the final q give the estimate and its CoV (sample standard error /
   estimate); with ``level_share`` > 0 the final q's kernel part is a ``KernelMixture``
   of the adapted kernel density and, in that share, the one on the subset levels' final
   points (the adaptation's resampling can lose a part of A the levels found and then
   meets it only through rare heavy weights; 0.3 by default, measured in
   ``docs/sampler.md``). Only this stage's draws enter the
   estimate (its proposal is fixed given the earlier stages, so the estimate is
   unbiased); every limit-state evaluation of all three stages is counted in
   ``n_evaluations``.

With g close to the model restricted to A the per-draw squared CoV is about
``alpha / (1 - alpha)`` whatever P(A) is; measured figures are in ``docs/sampler.md``.

Samples of the model restricted to A come from independence Metropolis-Hastings chains
(Liu 1996, "Metropolized independent sampling") whose proposals are the final stage's
draws themselves (i.i.d. from q): a proposal ``z'`` replaces the state ``z`` with
probability ``min(1, w(z') / w(z))``, ``w = 1_A p / q``. Exact for its stationary law,
no new evaluations, honest diagnostics: acceptance, integrated autocorrelation time
(``sampler.methods.mcmc._tau``), effective sample size. More draws of q are made (and enter P(A)
too) until the chains' effective sample size reaches ``ess_target * n``, within the time
budget.

**Stratified** (``stratified_importance``, ``SubsetISSampler(stratify="always")``): the
model is a mixture, so ``P(A) = sum_s pi_s P_s(A)`` over its strata (``sampler.methods.strata``:
component x cut-in side, or component x the region's half-space envelope S when it has
one, ``SubsetISSampler(strat_envelope=True)``: then A lies inside S, the masses sum to
P(S) and each ``P_s`` is conditional on S; ``pi_s`` exact, ``P_s`` sampled exactly); one
subset-is per
stratum, budgeted by what its first levels reveal (strata probed and ordered nearest
first; levels of 1,000 points for the first stratum that reaches A, 200 for the others,
each cut at ``rel_floor`` (0.1 %) of the running total / ``pi_s`` with that bound reported;
a later stratum that holds more than all before it, i.e. was ordered wrongly, gets its
levels re-run with 1,000 points;
two adaptation rounds of 1,500 whose resampled centres keep their multiplicity, only for
strata holding >= 1 % of the total), the final ``n_is`` draws allocated in proportion to
the strata's estimated contributions (at least ``n_is_min`` each), variance
``sum pi_s^2 var_s``; the samples are drawn from the strata in proportion to their
estimated contributions, each stratum's by its own independence chains. A region's
separate modes (sides, components) then no longer depend on one Markov chain or kernel
density finding them all. The levels need a limit state that is not flat where the
quantity is (``ttc`` +inf for every non-closing cut-in, ``btn`` 0 wherever the ego never
reaches the cutter): ``region_limit_state`` gives continuous margins there. ``auto``
stratifies whenever the model has more than one stratum (``STRATIFY_AUTO``; measured in
``docs/sampler.md``).

``subset_importance(model, limit_state, seed)`` is the estimator as a function (any
vectorised z-space limit state, ``sampler.methods.subset.region_limit_state`` for a region);
``rare_probability(model, constraints, seed)`` the same for constraints;
``SubsetISSampler`` (name ``subset-is``) the sampler.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sampler.errors import EmptyRegionError, LevelsNotConvergedError, SamplerError
from sampler.methods.envelope import find_envelope
from sampler.methods.importance import (
    ImportanceStage,
    KernelMixture,
    KernelProposal,
    Proposal,
    ZDensity,
    independence_chain,
    kish_ess,
)
from sampler.methods.mcmc import _tau
from sampler.methods.problem import Draw, FloatArray, Pilot, Problem, ProgressFn, Sampler
from sampler.methods.strata import Stratum, halfspace_strata, make_strata
from sampler.methods.subset import LimitState, SubsetResult, region_limit_state, subset_simulation
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region

__all__ = ["RareResult", "StratumRun", "SubsetISSampler", "rare_probability",
           "stratified_importance", "subset_importance"]


@dataclass(frozen=True)
class RareResult:
    """Outcome of ``subset_importance``.

    Attributes
    ----------
    probability : float
        Importance-sampling estimate of ``P(g <= 0)`` under the model.
    cov : float
        Its coefficient of variation (sample standard error / estimate). ``cov_upper`` is
        the same figure (the interface ``sampler.methods.probability`` reads).
    n_evaluations : int
        Every limit-state evaluation: the subset stage's plus the importance draws.
    n_subset_evaluations, n_adapt, n_is, n_hits : int
        The subset stage's evaluations, the adaptation's draws, the final importance
        draws, and those of them inside A.
    ess_weights : float
        Kish's effective sample size of the weights of the final draws inside A.
    z, log_w : ndarray
        The importance draws inside A (z-space) and their ``log p - log q``, in draw order
        (stratified: ``log(pi_s p_s / q_s * n_is / n_s)``, on the same scale: in both,
        ``P = sum(exp(log_w)) / n_is``).
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
                      keep_stage: list[ImportanceStage] | None = None,
                      stratum: Stratum | None = None, level_share: float = 0.3) -> RareResult:
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
    stratum : Stratum, optional
        Estimate under this stratum of the model (``sampler.methods.strata``: one component,
        optionally one side) instead of the whole model: ``P_s(A)``.
    level_share : float
        Share of the final kernel density kept on the subset levels' final points, in
        [0, 1) (0: the adapted one alone; used only after adaptation rounds; default 0.3,
        measured in ``docs/sampler.md``).

    Raises
    ------
    SamplerError
        Bad settings, or the time budget was spent (how far it got is in the message).
    EmptyRegionError
        The subset levels did not reach the region (see ``subset_simulation``).
    """
    t0 = time.monotonic()
    ex = _explore(model, limit_state, seed, stratum=stratum, n_per_level=n_per_level,
                  alpha=alpha, inflate=inflate, p0=p0, n_adapt=n_adapt,
                  adapt_rounds=adapt_rounds, n_centres=n_centres, nu=nu, n_is=n_is,
                  max_seconds=max_seconds, min_probability=min_probability,
                  level_share=level_share)
    stage = ImportanceStage(ex.base, ex.limit_state, ex.proposal, ex.deadline, max_seconds)
    stage.add(int(n_is), ex.rng)
    if keep_stage is not None:
        keep_stage.append(stage)
    return _result(stage, ex.sub, t0, ex.n_adapt, inflate)


@dataclass
class _Explored:
    """What the subset levels and the adaptation rounds found (before the final stage)."""

    base: ZDensity
    limit_state: LimitState
    sub: SubsetResult
    proposal: Proposal
    n_adapt: int
    rng: np.random.Generator
    deadline: float
    pilot: tuple[float, float]  # the last adaptation round's (P, CoV); subset's without


def _in_stratum(stratum: Stratum, limit_state: LimitState) -> LimitState:
    """The limit state restricted to the stratum's half-space: rows outside it are outside
    A for this stratum (their weight is 0) and are not evaluated."""
    if stratum.a is None:
        return limit_state

    def g(z: FloatArray) -> FloatArray:
        out = np.full(z.shape[0], np.inf)
        ok = stratum.contains(z)
        if ok.any():
            out[ok] = np.asarray(limit_state(z[ok]), dtype=np.float64)
        return out

    return g


def _explore(model: CutInGMM, limit_state: LimitState, seed: int, *, stratum: Stratum | None,
             n_per_level: int, alpha: float, inflate: float, p0: float, n_adapt: int,
             adapt_rounds: int, n_centres: int, nu: float, n_is: int, max_seconds: float,
             min_probability: float, deadline: float | None = None,
             weighted_centres: bool = False, sub: SubsetResult | None = None,
             level_share: float = 0.3) -> _Explored:
    if not 0.0 < alpha < 1.0:
        raise SamplerError(f"alpha: must be in (0, 1), got {alpha!r}")
    if not 0.0 <= level_share < 1.0:
        raise SamplerError(f"level_share: must be in [0, 1), got {level_share!r}")
    if n_is < 2 or n_adapt < 2 or not inflate > 0 or adapt_rounds < 0 or n_centres < 2:
        raise SamplerError("n_is and n_adapt must be >= 2, inflate > 0, adapt_rounds >= 0, "
                           "n_centres >= 2")
    if deadline is None:
        deadline = time.monotonic() + float(max_seconds)
    base: ZDensity = model if stratum is None else stratum
    if stratum is not None:
        limit_state = _in_stratum(stratum, limit_state)
    if sub is None:
        sub = subset_simulation(model, limit_state, seed, n_per_level=n_per_level, p0=p0,
                                max_seconds=max(deadline - time.monotonic(), 1e-9),
                                min_probability=min_probability,
                                from_normal=None if stratum is None else stratum.from_normal)
    pts = np.unique(sub.z, axis=0)
    d = model.n_features
    if pts.shape[0] < d + 2:
        raise EmptyRegionError(
            f"subset-is: the final subset level holds {pts.shape[0]} distinct points inside "
            "the region, too few to fit an importance density; raise n_per_level",
            n_draws=sub.n_evaluations, n_hits=int(pts.shape[0]), p_upper=sub.probability)
    rng = np.random.default_rng([int(seed) % (2**32), 1])
    first = KernelProposal(base, pts, inflate, alpha, nu)
    proposal = first
    n_adapt_evals = 0
    pilot = (sub.probability, sub.cov)
    for _ in range(adapt_rounds):
        # importance draws inside A resampled by their weights (they follow the model
        # restricted to A, not the subset chains' coverage of it) are the next centres
        stage = ImportanceStage(base, limit_state, proposal, deadline, max_seconds)
        stage.add(int(n_adapt), rng)
        n_adapt_evals += stage.n
        pilot = stage.estimate()
        lw = stage.log_w
        ok = np.isfinite(lw)
        if ok.sum() > d + 1:
            zi, lwi = stage.z[ok], lw[ok]
            ww = np.exp(lwi - lwi.max())
            pick = rng.choice(zi.shape[0], size=min(n_centres, zi.shape[0]),
                              p=ww / ww.sum())
            # weighted_centres: each resampled centre as often as it was drawn (a part of A
            # the previous q under-covered, whose draws carry large weights, gets more
            # kernels), the bandwidth from the distinct ones; else the distinct centres
            if weighted_centres:
                proposal = KernelProposal(base, zi[pick], inflate, alpha, nu, shape=zi[pick],
                                          n_bandwidth=int(np.unique(pick).size))
            else:
                proposal = KernelProposal(base, zi[np.unique(pick)], inflate, alpha, nu,
                                          shape=zi[pick])
    final: Proposal = proposal
    if level_share > 0 and proposal is not first:
        # the kernel density on the subset levels' final points keeps a share: the
        # adaptation's resampling can lose a part of A that the levels found
        final = KernelMixture(base, [proposal, first], [1.0 - level_share, level_share],
                              alpha)
    return _Explored(base, limit_state, sub, final, n_adapt_evals, rng, deadline, pilot)


def _level_share(prop: Proposal) -> float:
    """The share of the subset levels' kernel density in a final proposal (0 without)."""
    return float(prop.shares[1]) if isinstance(prop, KernelMixture) else 0.0


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
                  "level_share": _level_share(prop),
                  "centres_from": ("importance draws inside A resampled by weight"
                                   if n_adapt else "final subset level")},
        seconds=time.monotonic() - t0)


@dataclass
class StratumRun:
    """One stratum of a stratified run: its final importance stage (None when its subset
    levels found no mass in it) and what it contributes."""

    stratum: Stratum
    stage: ImportanceStage | None
    sub: SubsetResult | None
    n_evaluations: int  # subset levels + adaptation (the final stage's draws: stage.n)
    p_upper: float = 0.0  # empty strata: the upper bound of P_s(A) from the levels
    note: str = ""  # empty strata: why (the subset stage's message)

    def estimate(self) -> tuple[float, float]:
        """(P_s(A), its standard error); (0, 0) for an empty stratum."""
        if self.stage is None:
            return 0.0, 0.0
        p, cov = self.stage.estimate()
        return p, (cov * p if p > 0 else 0.0)


def stratified_importance(model: CutInGMM, limit_state: LimitState, seed: int, *,
                          strata: list[Stratum] | None = None, n_per_level: int = 1000,
                          n_is: int = 4000, n_is_min: int = 300, alpha: float = 0.1,
                          inflate: float = 1.3, p0: float = 0.1, n_adapt: int = 1500,
                          adapt_rounds: int = 2, n_centres: int = 300, nu: float = 5.0,
                          max_seconds: float = 120.0, min_probability: float = 1e-14,
                          n_probe: int = 200, rel_floor: float = 1e-3,
                          adapt_share: float = 0.01, n_per_level_rest: int = 200,
                          weighted_centres: bool = True, level_share: float = 0.3,
                          keep_runs: list[StratumRun] | None = None) -> RareResult:
    """``P(A) = sum_s pi_s P_s(A)`` over the model's strata (``sampler.methods.strata``: component
    x cut-in side), each ``P_s(A)`` by subset-is under that stratum.

    Budget by what each stratum's first levels reveal:

    1. ``n_probe`` exact draws per stratum order the strata by their limit state's lower
       decile (the strata nearest the region first; the probe draws count as evaluations
       and do not enter the estimate);
    2. in that order, each stratum's subset levels (``n_per_level``; ``n_per_level_rest``
       once a stratum before it has reached A) run down to
       ``max(min_probability, rel_floor * T / pi_s)``, ``T`` the sum of the contributions
       ``pi_s P_s`` the levels of the strata before it found. A stratum run with
       ``n_per_level_rest`` whose levels find more than ``T`` (the probes ordered it
       wrongly: it is the main one) is re-run with ``n_per_level`` (its kernel density's
       centres come from its final level; the discarded levels are counted). A stratum
       cut at the floor without reaching A is bounded, not estimated:
       ``pi_s P_s(A) <= pi_s P_s(g <= b)``, its levels' last probability (an estimate of an
       upper bound; below ``rel_floor`` of the running total); its bound is reported
       (``neglected_upper``, per stratum ``empty_upper`` and ``empty_reason``) and it
       counts 0;
    3. adaptation rounds (``adapt_rounds`` of ``n_adapt``) only for the strata whose
       levels' contribution is at least ``adapt_share`` of the total; the others keep the
       kernel density on their final level (still unbiased, at most a share
       ``adapt_share`` each of the variance budget); with ``weighted_centres`` the
       resampled centres keep their multiplicity (else the distinct ones, as the plain
       run; measured against each other in ``docs/sampler.md``); ``level_share`` as in
       ``subset_importance``;
    4. the final importance draws, ``n_is`` in all, in proportion to the strata's
       estimated contributions (last adaptation round, else the levels), at least
       ``n_is_min`` each: every stratum that reached A gets an unbiased estimate of its
       own.

    The estimate is unbiased given the strata's proposals, up to the reported bounds of
    the cut strata; its variance is ``sum pi_s^2 var_s``.

    Raises
    ------
    SamplerError
        Bad settings, or the time budget (whole run) was spent.
    EmptyRegionError
        No stratum reached the region.
    """
    t0 = time.monotonic()
    deadline = t0 + float(max_seconds)
    strata = make_strata(model) if strata is None else strata
    if not strata:
        raise SamplerError("stratified subset-is: no stratum (the model has no component)")
    if n_is_min < 2 or n_is < n_is_min:
        raise SamplerError("n_is_min must be >= 2 and n_is >= n_is_min")
    if n_probe < 0 or not 0.0 <= rel_floor < 1.0 or not 0.0 <= adapt_share <= 1.0:
        raise SamplerError("n_probe >= 0, 0 <= rel_floor < 1, 0 <= adapt_share <= 1")
    # 1. probes: the strata nearest the region first (so that T is known early)
    near = np.zeros(len(strata))
    n_probe_evals = [0] * len(strata)
    if n_probe > 0:
        for i, st in enumerate(strata):
            rng_p = np.random.default_rng([int(seed) % (2**32), 11, i])
            gp = np.asarray(_in_stratum(st, limit_state)(st.sample_z(int(n_probe), rng_p)))
            n_probe_evals[i] = int(n_probe)
            near[i] = float(np.quantile(np.where(np.isfinite(gp), gp, 1e300), 0.1))
    order = sorted(range(len(strata)), key=lambda i: (near[i], -strata[i].mass))
    # 2. subset levels, down to a floor relative to what the strata before found
    runs: list[StratumRun | None] = [None] * len(strata)
    subs: list[SubsetResult | None] = [None] * len(strata)
    total = 0.0
    def levels(i: int, n: int, floor: float) -> SubsetResult:
        """Stratum i's subset levels with n points per level, down to floor."""
        return subset_simulation(model, _in_stratum(strata[i], limit_state),
                                 _stratum_seed(seed, i), n_per_level=n, p0=p0,
                                 max_seconds=max(deadline - time.monotonic(), 1e-9),
                                 min_probability=floor, from_normal=strata[i].from_normal)

    def explore(i: int, sub: SubsetResult, rounds: int) -> _Explored:
        """Stratum i's adaptation from its levels (rounds: 0 keeps the levels' density)."""
        return _explore(model, limit_state, _stratum_seed(seed, i), stratum=strata[i],
                        n_per_level=n_per_level, alpha=alpha, inflate=inflate, p0=p0,
                        n_adapt=n_adapt, adapt_rounds=rounds, n_centres=n_centres, nu=nu,
                        n_is=n_is, max_seconds=max_seconds, min_probability=min_probability,
                        deadline=deadline, weighted_centres=weighted_centres, sub=sub,
                        level_share=level_share)

    for i in order:
        st = strata[i]
        if time.monotonic() > deadline:
            raise SamplerError(f"stratified subset-is: stopped after max_seconds="
                               f"{max_seconds:g} s exploring stratum {i + 1} of {len(strata)} "
                               f"({st.label}); raise max_seconds")
        floor = min_probability
        if total > 0 and st.mass > 0:
            floor = min(max(min_probability, rel_floor * total / st.mass), 0.5)
        rerun_evals = 0
        try:
            # once a stratum has reached A, the others' levels only have to show that
            # they are negligible or find A for their kernel density: fewer points
            sub = levels(i, n_per_level if total == 0 else n_per_level_rest, floor)
            if total > 0 and n_per_level_rest < n_per_level and st.mass * sub.probability > total:
                # the probes ordered it wrongly: it holds more than all strata before it,
                # so its kernel density needs the full levels (from n_per_level_rest points
                # the final level has too few distinct centres: measured 0.47 and 4e-8 of
                # the reference on `ttc<3 & btn>0.5`, seeds 1014 and 1026)
                rerun_evals = sub.n_evaluations
                sub = levels(i, n_per_level, min_probability)
        except LevelsNotConvergedError as exc:
            # the levels met A but could not converge on it (a thin region): once more with
            # THIN_RETRY times the points per level, else refuse (the stratum may hold
            # most of P(A); counting it 0 would be silently wrong)
            try:
                sub = levels(i, THIN_RETRY * n_per_level, floor)
            except LevelsNotConvergedError as again:
                raise _unconverged(st, again, THIN_RETRY * n_per_level) from None
            except EmptyRegionError as below:
                runs[i] = StratumRun(st, None, None, int(exc.n_draws) + int(below.n_draws)
                                     + n_probe_evals[i],
                                     float(below.p_upper) if math.isfinite(below.p_upper)
                                     else floor, str(below).splitlines()[0])
                continue
            rerun_evals += int(exc.n_draws)
        except EmptyRegionError as exc:
            if exc.stalled is not None:
                # the levels stalled (their chains did not move): "empty" bounds nothing
                # here (on `2.9 < ttc < 3 & btn > 0.5` such a stratum held nearly all of
                # P(A)); once more with THIN_RETRY times the points, as above
                try:
                    sub = levels(i, THIN_RETRY * n_per_level, floor)
                except LevelsNotConvergedError as again:
                    raise _unconverged(st, again, THIN_RETRY * n_per_level) from None
                except EmptyRegionError as below:
                    rerun_evals += int(exc.n_draws)  # the first attempt's; below's next
                    exc = below
                else:
                    rerun_evals += int(exc.n_draws)
                    subs[i] = sub
                    n_probe_evals[i] += rerun_evals
                    total += st.mass * sub.probability
                    continue
            why = str(exc).splitlines()[0]
            if floor > min_probability and not rerun_evals:
                why = (f"cut at {floor:.3g} = rel_floor x the running total / pi_s: "
                       f"contribution below {rel_floor:g} of the strata before it ({why})")
            runs[i] = StratumRun(st, None, None,
                                 int(exc.n_draws) + n_probe_evals[i] + rerun_evals,
                                 float(exc.p_upper) if math.isfinite(exc.p_upper) else floor,
                                 why)
            continue
        subs[i] = sub
        n_probe_evals[i] += rerun_evals  # counted with the probes (not in sub)
        total += st.mass * sub.probability
    live = [i for i in range(len(strata)) if subs[i] is not None]
    if not live:
        done = [r for r in runs if r is not None]
        raise EmptyRegionError(
            f"stratified subset-is: the subset levels reached the region in none of the "
            f"{len(strata)} strata", n_draws=sum(r.n_evaluations for r in done), n_hits=0,
            p_upper=sum(r.stratum.mass * r.p_upper for r in done))
    # 3. adaptation where the contribution is worth it
    explored: dict[int, _Explored] = {}
    for i in live:
        st, found = strata[i], subs[i]
        assert found is not None
        sub = found
        big = total > 0 and st.mass * sub.probability >= adapt_share * total
        try:
            ex = explore(i, sub, adapt_rounds if big else 0)
        except EmptyRegionError as exc:
            if st.mass * sub.probability < rel_floor * total:  # negligible: bounded
                runs[i] = StratumRun(st, None, None, sub.n_evaluations + n_probe_evals[i],
                                     sub.probability, str(exc).splitlines()[0])
                continue
            # too few distinct points in a stratum that matters (a thin region: the final
            # level's chains barely moved): its levels once more with more points
            n_probe_evals[i] += sub.n_evaluations
            try:
                sub = levels(i, THIN_RETRY * n_per_level, min_probability)
                ex = explore(i, sub, adapt_rounds if big else 0)
            except (EmptyRegionError, LevelsNotConvergedError) as again:
                raise _unconverged(st, again, THIN_RETRY * n_per_level) from None
        explored[i] = ex
        runs[i] = StratumRun(st, None, ex.sub,
                             n_probe_evals[i] + ex.sub.n_evaluations + ex.n_adapt)
    if not explored:
        done = [r for r in runs if r is not None]
        raise EmptyRegionError(
            "stratified subset-is: no stratum's final subset level held enough distinct "
            "points inside the region for an importance density; raise n_per_level",
            n_draws=sum(r.n_evaluations for r in done), n_hits=0)
    # 4. the final importance draws, by estimated contribution
    keys = list(explored)
    contrib = np.array([strata[i].mass * max(explored[i].pilot[0], 0.0) for i in keys])
    share = contrib / contrib.sum() if contrib.sum() > 0 else np.full(len(keys), 1 / len(keys))
    for i, sh in zip(keys, share, strict=True):
        ex_i = explored[i]
        stage = ImportanceStage(ex_i.base, ex_i.limit_state, ex_i.proposal, deadline,
                                max_seconds)
        stage.add(max(int(n_is_min), round(n_is * float(sh))), ex_i.rng)
        run_i = runs[i]
        assert run_i is not None
        run_i.stage = stage
    out = [r for r in runs if r is not None]
    if keep_runs is not None:
        keep_runs.extend(out)
    return _stratified_result(out, t0, inflate)


#: a stratum whose levels met the region but could not converge on it, or whose final
#: level held too few distinct points for its kernel density while it matters, gets its
#: levels once more with this many times the points per level (a thin region: measured on
#: `ttc<3 & ttc>2.9 & btn>0.4`, docs/sampler.md); if that fails too, the run refuses
THIN_RETRY = 4


def _unconverged(st: Stratum, exc: Exception, n: int) -> LevelsNotConvergedError:
    """The refusal of a stratum that matters but could not be estimated."""
    return LevelsNotConvergedError(
        f"stratified subset-is: stratum {st.label}: {str(exc).splitlines()[0]}; also with "
        f"{n} points per level. Leaving it out would make P(A) silently too small, so no "
        "estimate: widen the region (a narrow band of a kinematic quantity such as ttc is "
        "the usual cause) or choose method=mcmc or rejection",
        n_draws=int(getattr(exc, "n_draws", 0)), n_hits=int(getattr(exc, "n_hits", 0)))


def _stratum_seed(seed: int, i: int) -> int:
    """A distinct, deterministic seed per stratum."""
    return int(np.random.default_rng([int(seed) % (2**32), 7, i]).integers(0, 2**31 - 1))


def _stratified_result(runs: list[StratumRun], t0: float, inflate: float) -> RareResult:
    p = 0.0
    var = 0.0
    zs: list[FloatArray] = []
    lws: list[FloatArray] = []
    strata: list[dict[str, Any]] = []
    n_sub = n_adapt = n_is = n_hits = 0
    best: tuple[float, SubsetResult] | None = None
    for r in runs:
        ps, se = r.estimate()
        pi = r.stratum.mass
        p += pi * ps
        var += (pi * se) ** 2
        info: dict[str, Any] = {"stratum": r.stratum.label, "mass": pi, "p": ps,
                                "cov": se / ps if ps > 0 else None,
                                "contribution": pi * ps,
                                "n_evaluations": r.n_evaluations + (r.stage.n if r.stage
                                                                    else 0)}
        if r.sub is not None:
            n_sub += r.sub.n_evaluations
            n_adapt += r.n_evaluations - r.sub.n_evaluations
            info["subset_levels"] = len(r.sub.thresholds)
        else:
            n_sub += r.n_evaluations
            info["empty_upper"] = pi * r.p_upper
            info["empty_reason"] = r.note
        if r.stage is not None:
            n_is += r.stage.n
            lw = r.stage.log_w
            inside = np.isfinite(lw)
            n_hits += int(inside.sum())
            info["n_is"] = r.stage.n
            info["level_share"] = _level_share(r.stage.proposal)
            info["n_hits"] = int(inside.sum())
            zs.append(r.stage.z[inside])
            # weights relative to the whole model, on the plain result's scale:
            # P = sum(exp(log_w)) / n_is as there (each stratum's draws estimate pi_s P_s:
            # pi_s p_s / q_s / n_s per draw, times the total n_is)
            lws.append(lw[inside] + math.log(pi) - math.log(r.stage.n))
            if r.sub is not None and (best is None or pi * ps > best[0]):
                best = (pi * ps, r.sub)
        strata.append(info)
    if best is None or p <= 0:
        raise EmptyRegionError("stratified subset-is: no importance draw fell inside the "
                               "region in any stratum; raise n_is",
                               n_draws=n_sub + n_adapt + n_is, n_hits=0)
    lw_all = np.concatenate(lws) + math.log(max(n_is, 1))
    return RareResult(
        probability=p, cov=math.sqrt(var) / p, n_evaluations=n_sub + n_adapt + n_is,
        n_subset_evaluations=n_sub, n_adapt=n_adapt, n_is=n_is, n_hits=n_hits,
        ess_weights=kish_ess(lw_all), z=np.concatenate(zs, axis=0), log_w=lw_all,
        subset=best[1],
        proposal={"kind": "stratified defensive kernel densities", "inflate": inflate,
                  "strata": strata,
                  "neglected_upper": sum(s.get("empty_upper", 0.0) for s in strata)},
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
    stratify : {"auto", "always", "never"}
        ``always``: ``stratified_importance`` (one subset-is per stratum of the model:
        component x cut-in side, or component x envelope, ``strat_envelope``);
        ``never``: one subset-is on the whole model; ``auto``: see ``STRATIFY_AUTO``.
    strat_per_level, strat_n_adapt, strat_n_is_min :
        The stratified run's ``n_per_level``, ``n_adapt`` and ``n_is_min``
        (``stratified_importance``); ``n_is`` is shared.
    level_share : float
        See ``subset_importance`` (both paths; per stratum in the stratified one).
    strat_envelope : bool
        Stratify inside the region's half-space envelope when it has one (component x S,
        ``_strata``): the levels then only go down to P(A | S), and nothing outside S is
        simulated (measured in ``docs/sampler.md``).
    strat_env_n_adapt : int
        ``n_adapt`` of a run stratified inside the envelope (its levels cost less, and the
        adaptation needs more draws there: on a closed-form region the reported CoV was
        27 % low with 1,500 and right with 2,000; on the TNO envelope regions 2,000 kept
        0.95-0.97 of the seeds in 2 CoV, and 3,000 cost more evaluations for no better
        coverage; ``docs/sampler.md``).
    """

    name = "subset-is"

    def __init__(self, n_per_level: int = 1000, n_is: int = 4000, alpha: float = 0.1,
                 inflate: float = 1.3, n_adapt: int = 1500, adapt_rounds: int = 2,
                 n_centres: int = 300, max_seconds: float = 120.0,
                 min_probability: float = 1e-14, ess_target: float = 0.25,
                 n_chains: int = 4, stratify: str = "auto", strat_per_level: int = 1000,
                 strat_n_adapt: int = 1500, strat_n_is_min: int = 300,
                 strat_split_side: bool = True, strat_weighted_centres: bool = True,
                 level_share: float = 0.3, strat_envelope: bool = True,
                 strat_env_n_adapt: int = 2000) -> None:
        if stratify not in ("auto", "always", "never"):
            raise SamplerError(f"stratify: expected auto, always or never, got {stratify!r}")
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
        self.stratify = stratify
        self.strat_per_level = int(strat_per_level)
        self.strat_n_adapt = int(strat_n_adapt)
        self.strat_n_is_min = int(strat_n_is_min)
        self.strat_split_side = bool(strat_split_side)
        self.strat_weighted_centres = bool(strat_weighted_centres)
        self.strat_envelope = bool(strat_envelope)
        self.strat_env_n_adapt = int(strat_env_n_adapt)
        if not 0.0 <= level_share < 1.0:
            raise SamplerError(f"level_share: must be in [0, 1), got {level_share!r}")
        self.level_share = float(level_share)

    def _limit_state(self, problem: Problem, rng: np.random.Generator) -> LimitState:
        limit_state = region_limit_state(problem.model, problem.region, rng)

        def counted(z: FloatArray) -> FloatArray:
            problem.n_evals += z.shape[0]
            return limit_state(z)

        return counted

    def _strata(self, problem: Problem) -> tuple[list[Stratum], bool]:
        """The strata of a stratified run and whether they lie inside an envelope: with
        ``strat_envelope`` and a region that has a half-space envelope S
        (``sampler.methods.envelope``, e.g. from ``ttc<3``), component x S (every stratum inside
        S, which holds the region: each P_s(A) is conditional on S, and no simulation is
        spent outside it); else component x cut-in side."""
        if self.strat_envelope:
            env = find_envelope(problem.model, problem.region)
            if env is not None:
                return halfspace_strata(problem.model, env.a, env.b, env.source), True
        return make_strata(problem.model, self.strat_split_side), False

    def _stratified(self, problem: Problem) -> bool:
        if self.stratify == "always":
            return True
        if self.stratify == "never":
            return False
        return STRATIFY_AUTO(problem)

    def run(self, problem: Problem, rng: np.random.Generator,
            keep_stage: list[ImportanceStage] | None = None,
            keep_runs: list[StratumRun] | None = None) -> RareResult:
        """P(A) of the problem's region (also used without samples). ``keep_stage``
        receives the importance stage of an unstratified run, ``keep_runs`` the strata of
        a stratified one."""
        limit_state = self._limit_state(problem, rng)
        seed = int(rng.integers(0, 2**31 - 1))
        common = {"n_is": self.n_is, "alpha": self.alpha, "inflate": self.inflate,
                  "adapt_rounds": self.adapt_rounds, "n_centres": self.n_centres,
                  "max_seconds": self.max_seconds, "min_probability": self.min_probability,
                  "level_share": self.level_share}
        if self._stratified(problem):
            strata, inside_envelope = self._strata(problem)
            return stratified_importance(problem.model, limit_state, seed,
                                         strata=strata,
                                         n_per_level=self.strat_per_level,
                                         n_adapt=(self.strat_env_n_adapt if inside_envelope
                                                  else self.strat_n_adapt),
                                         n_is_min=self.strat_n_is_min,
                                         weighted_centres=self.strat_weighted_centres,
                                         keep_runs=keep_runs,
                                         **common)  # type: ignore[arg-type]
        return subset_importance(problem.model, limit_state, seed,
                                 n_per_level=self.n_per_level, n_adapt=self.n_adapt,
                                 keep_stage=keep_stage, **common)  # type: ignore[arg-type]

    def _chains(self, stage: ImportanceStage, n: int, rng: np.random.Generator,
                t_start: float, warnings: list[str], what: str
                ) -> tuple[FloatArray, dict[str, Any]]:
        """``n`` samples of the stage's restricted law from independence chains over its
        draws (more draws until the chains' ESS reaches ``ess_target * n``)."""
        while True:
            states, acc = independence_chain(stage.log_w, rng, self.n_chains)
            zs = stage.z
            tau = _tau(zs[states])  # chain (steps, chains, d)
            tau_max = float(tau.max())
            burn = min(math.ceil(2 * tau_max), states.shape[0] // 2)
            post = states[burn:]
            ess = post.size / tau_max
            if ess >= self.ess_target * n:
                break
            if time.monotonic() - t_start > 0.8 * self.max_seconds:
                warnings.append(f"{what}time budget nearly spent with ESS {ess:.0f} < "
                                f"{self.ess_target * n:.0f}: the samples are more correlated "
                                "than asked")
                break
            need = self.ess_target * n / max(ess, 1.0) * stage.n - stage.n
            stage.add(int(min(max(need * 1.2, 2000), 8 * stage.n)), rng)
        flat = post.reshape(-1)  # time-major: consecutive entries are different chains
        pick = flat[np.linspace(0, flat.size - 1, n).round().astype(int)]
        return zs[pick], {"acceptance": acc, "tau": tau, "tau_max": tau_max, "burn_in": burn,
                          "n_steps": int(states.shape[0]), "ess": ess,
                          "n_distinct": int(np.unique(pick).size)}

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        t_start = time.monotonic()
        stages: list[ImportanceStage] = []
        runs: list[StratumRun] = []
        res = self.run(problem, rng, keep_stage=stages, keep_runs=runs)
        warnings: list[str] = []
        if not runs:
            z, ch = self._chains(stages[0], n, rng, t_start, warnings, "")
            res = _result(stages[0], res.subset, t_start, res.n_adapt, self.inflate)
            diag = {"acceptance_fraction": ch["acceptance"].tolist(),
                    "acceptance_mean": float(ch["acceptance"].mean()),
                    "tau": ch["tau"].tolist(), "tau_max": ch["tau_max"],
                    "burn_in": ch["burn_in"], "n_steps": ch["n_steps"],
                    "ess": float(min(n, ch["ess"])), "ess_chain": float(ch["ess"]),
                    "n_distinct": ch["n_distinct"]}
        else:
            # n samples from the strata in proportion to their estimated contributions
            # (largest remainders), each stratum's by its own independence chains
            contrib = np.array([r.stratum.mass * r.estimate()[0] for r in runs])
            counts = _apportion(n, contrib)
            parts: list[FloatArray] = []
            per: list[dict[str, Any]] = []
            for r, c in zip(runs, counts, strict=True):
                if c == 0 or r.stage is None:
                    continue
                z_s, ch = self._chains(r.stage, int(c), rng, t_start, warnings,
                                       f"{r.stratum.label}: ")
                parts.append(z_s)
                per.append({"stratum": r.stratum.label, "n": int(c),
                            "acceptance_mean": float(ch["acceptance"].mean()),
                            "tau_max": ch["tau_max"], "ess_chain": float(ch["ess"]),
                            "n_distinct": ch["n_distinct"]})
            z = np.concatenate(parts, axis=0)
            # shuffled (deterministically) so that a prefix is not one stratum
            z = z[rng.permutation(z.shape[0])]
            res = _stratified_result(runs, t_start, self.inflate)
            ess = sum(min(p["n"], p["ess_chain"]) for p in per)
            w = np.array([p["n"] for p in per], dtype=float)
            diag = {"acceptance_mean": float(np.average([p["acceptance_mean"] for p in per],
                                                        weights=w)),
                    "tau_max": float(max(p["tau_max"] for p in per)),
                    "ess": float(min(n, ess)), "ess_chain": float(ess),
                    "n_distinct": int(sum(p["n_distinct"] for p in per)), "strata": per}
        if progress is not None:
            progress("subset-is", n, n)
        diag = {"subset_is": res.summary(), "n_evaluations": problem.n_evals,
                "n_chains": self.n_chains, **diag, "warnings": warnings}
        return Draw(z=np.ascontiguousarray(z), method=self.name, diagnostics=diag,
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits, subset=res)


def _apportion(n: int, weights: FloatArray) -> NDArray[np.int64]:
    """``n`` split in proportion to ``weights`` (largest remainders; deterministic)."""
    w = np.maximum(np.asarray(weights, dtype=np.float64), 0.0)
    if not w.sum() > 0:
        w = np.ones_like(w)
    exact = n * w / w.sum()
    out = np.floor(exact).astype(np.int64)
    rest = n - int(out.sum())
    if rest > 0:
        out[np.argsort(-(exact - out), kind="stable")[:rest]] += 1
    return out


#: ``auto`` stratifies models with 2 .. this many strata (a fitted scenario model: K <= 8
#: components x 2 sides); not e.g. the pooled bootstrap replicates (B x K components),
#: where one subset-is per stratum would cost hundreds of runs
MAX_AUTO_STRATA = 16


def _several_strata(problem: Problem) -> bool:
    """Stratify whenever the model has 2 .. ``MAX_AUTO_STRATA`` strata (measured in
    ``docs/sampler.md``: with the continuous limit states and the budget by stratum, the
    stratified run is within the targets on the single-mode regions too, and only it is
    on the multi-mode ones)."""
    model = problem.model
    k = int(np.count_nonzero(model.weights_ > 0))
    n = k * (2 if "p_y1" in model.features_ else 1)
    return 2 <= n <= MAX_AUTO_STRATA


#: whether ``stratify="auto"`` stratifies a problem
STRATIFY_AUTO = _several_strata


def rare_probability(model: CutInGMM, constraints: Any, seed: int, *,
                     lane_width: float | None = None, physical_bounds: bool = True,
                     **settings: Any) -> RareResult:
    """P(A and B) of a region (constraints as for ``sample``) by subset-is, as a function
    (e.g. once per bootstrap replicate of the model). ``settings`` go to
    ``SubsetISSampler``. Divide by P(B) (``sampler.methods.probability``) for P(A); or use
    ``estimate_p_region``, which does both (and picks subset-is for rare regions)."""
    region = constraints if isinstance(constraints, Region) else Region.from_constraints(
        constraints, lane_width=model.lane_width_ if lane_width is None else lane_width,
        physical_bounds=physical_bounds)
    problem = Problem(model, region, use_envelope=False)
    return SubsetISSampler(**settings).run(problem, np.random.default_rng(seed))
