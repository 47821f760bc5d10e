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
(``sampler.methods.mcmc.integrated_time``), effective sample size. More draws of q are made
(and enter P(A) too) until the chains' effective sample size reaches ``ess_target * n``,
within the time budget.

**Stratified** (``stratified_importance``, ``StrataSettings(stratify="always")``): the
model is a mixture, so ``P(A) = sum_s pi_s P_s(A)`` over its strata (``sampler.methods.strata``:
component x cut-in side, or component x the region's half-space envelope S when it has
one, ``StrataSettings(envelope=True)``: then A lies inside S, the masses sum to
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
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

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
from sampler.methods.mcmc import integrated_time
from sampler.methods.problem import Draw, FloatArray, Pilot, Problem, ProgressFn, Run, Sampler
from sampler.methods.strata import Stratum, halfspace_strata, make_strata
from sampler.methods.subset import (
    LimitState,
    SubsetResult,
    estimate_from_levels,
    region_limit_state,
    subset_simulation,
)
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region

if TYPE_CHECKING:  # annotations only (probability builds on the samplers)
    from sampler.methods.probability import PRegion

__all__ = ["ChainSettings", "ImportanceSettings", "RareResult", "StrataBudget",
           "StrataSettings", "StratumRun", "SubsetISSampler", "rare_probability",
           "stratified_importance", "subset_importance"]


@dataclass(frozen=True)
class ImportanceSettings:
    """Settings of one subset-is run (``subset_importance``; per stratum in
    ``stratified_importance``).

    Attributes
    ----------
    n_per_level : int
        Points per subset level (the stage that finds the region).
    n_is : int
        Importance draws of the final proposal (the estimate).
    alpha : float
        The model's share of the proposal, in (0, 1).
    inflate : float
        Scale of the kernels' standard deviations (on Silverman's bandwidth).
    p0 : float
        Conditional probability of each subset level.
    n_adapt, adapt_rounds : int
        Draws per adaptation round, and rounds.
    n_centres : int
        Centres resampled after each adaptation round (distinct ones are kept).
    nu : float
        Degrees of freedom of the kernels (Student t).
    max_seconds, min_probability : float
        Time budget of the whole run; the subset stage gives up below this mass.
    level_share : float
        Share of the final kernel density kept on the subset levels' final points, in
        [0, 1) (0: the adapted one alone; used only after adaptation rounds; default 0.3,
        measured in ``docs/sampler.md``).

    Raises
    ------
    SamplerError
        A setting out of its range.
    """

    n_per_level: int = 1000
    n_is: int = 4000
    alpha: float = 0.1
    inflate: float = 1.3
    p0: float = 0.1
    n_adapt: int = 1500
    adapt_rounds: int = 2
    n_centres: int = 300
    nu: float = 5.0
    max_seconds: float = 120.0
    min_probability: float = 1e-14
    level_share: float = 0.3

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha < 1.0:
            raise SamplerError(f"alpha: must be in (0, 1), got {self.alpha!r}")
        if not 0.0 <= self.level_share < 1.0:
            raise SamplerError(f"level_share: must be in [0, 1), got {self.level_share!r}")
        if (self.n_is < 2 or self.n_adapt < 2 or not self.inflate > 0
                or self.adapt_rounds < 0 or self.n_centres < 2):
            raise SamplerError("n_is and n_adapt must be >= 2, inflate > 0, "
                               "adapt_rounds >= 0, n_centres >= 2")


@dataclass(frozen=True)
class StrataBudget:
    """How ``stratified_importance`` shares its budget among the strata (its steps 1-4).

    Attributes
    ----------
    n_is_min : int
        Final importance draws of a stratum that reached A, at least.
    n_probe : int
        Exact draws per stratum that order the strata (0: by mass alone).
    rel_floor : float
        A stratum's levels stop at ``rel_floor`` x the running total / its mass.
    adapt_share : float
        Adaptation rounds only for strata holding at least this share of the total.
    n_per_level_rest : int
        Points per level once a stratum before has reached A.
    weighted_centres : bool
        Resampled centres keep their multiplicity (else the distinct ones).
    """

    n_is_min: int = 300
    n_probe: int = 200
    rel_floor: float = 1e-3
    adapt_share: float = 0.01
    n_per_level_rest: int = 200
    weighted_centres: bool = True


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


def subset_importance(model: CutInGMM, limit_state: LimitState, seed: int,
                      settings: ImportanceSettings | None = None, *,
                      keep_stage: list[ImportanceStage] | None = None,
                      stratum: Stratum | None = None) -> RareResult:
    """Estimate ``P(limit_state(z) <= 0)`` under the model: subset levels, then importance
    sampling from a defensive kernel density (module docstring).

    Parameters
    ----------
    settings : ImportanceSettings, optional
        Levels, proposal, adaptation and budget (defaults: ``ImportanceSettings()``).
    keep_stage : list, optional
        If given, the importance stage is appended to it (to draw more later).
    stratum : Stratum, optional
        Estimate under this stratum of the model (``sampler.methods.strata``: one component,
        optionally one side) instead of the whole model: ``P_s(A)``.

    Raises
    ------
    SamplerError
        Bad settings, or the time budget was spent (how far it got is in the message).
    EmptyRegionError
        The subset levels did not reach the region (see ``subset_simulation``).
    """
    cfg = settings or ImportanceSettings()
    t0 = time.monotonic()
    ex = _explore(model, limit_state, seed, cfg, stratum=stratum)
    stage = ImportanceStage(ex.base, ex.limit_state, ex.proposal, ex.deadline, cfg.max_seconds)
    stage.add(int(cfg.n_is), ex.rng)
    if keep_stage is not None:
        keep_stage.append(stage)
    return _result(stage, ex.sub, t0, ex.n_adapt, cfg.inflate)


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


def _explore(model: CutInGMM, limit_state: LimitState, seed: int, cfg: ImportanceSettings, *,
             stratum: Stratum | None = None, deadline: float | None = None,
             weighted_centres: bool = False, sub: SubsetResult | None = None,
             adapt_rounds: int | None = None) -> _Explored:
    """The subset levels (unless ``sub`` is given) and the adaptation rounds
    (``adapt_rounds``, default the settings') of one subset-is run."""
    rounds = cfg.adapt_rounds if adapt_rounds is None else adapt_rounds
    if deadline is None:
        deadline = time.monotonic() + float(cfg.max_seconds)
    base: ZDensity = model if stratum is None else stratum
    if stratum is not None:
        limit_state = _in_stratum(stratum, limit_state)
    if sub is None:
        sub = subset_simulation(model, limit_state, seed, n_per_level=cfg.n_per_level,
                                p0=cfg.p0, max_seconds=max(deadline - time.monotonic(), 1e-9),
                                min_probability=cfg.min_probability,
                                from_normal=None if stratum is None else stratum.from_normal)
    pts = np.unique(sub.z, axis=0)
    d = model.n_features
    if pts.shape[0] < d + 2:
        raise EmptyRegionError(
            f"subset-is: the final subset level holds {pts.shape[0]} distinct points inside "
            "the region, too few to fit an importance density; raise n_per_level",
            n_draws=sub.n_evaluations, n_hits=int(pts.shape[0]), p_upper=sub.probability)
    rng = np.random.default_rng([int(seed) % (2**32), 1])
    first = KernelProposal(base, pts, cfg.inflate, cfg.alpha, cfg.nu)
    proposal = first
    n_adapt_evals = 0
    pilot = (sub.probability, sub.cov)
    for _ in range(rounds):
        # importance draws inside A resampled by their weights (they follow the model
        # restricted to A, not the subset chains' coverage of it) are the next centres
        stage = ImportanceStage(base, limit_state, proposal, deadline, cfg.max_seconds)
        stage.add(int(cfg.n_adapt), rng)
        n_adapt_evals += stage.n
        pilot = stage.estimate()
        lw = stage.log_w
        ok = np.isfinite(lw)
        if ok.sum() > d + 1:
            proposal = _recentred(base, stage.z[ok], lw[ok], cfg, rng, weighted_centres)
    final: Proposal = proposal
    if cfg.level_share > 0 and proposal is not first:
        # the kernel density on the subset levels' final points keeps a share: the
        # adaptation's resampling can lose a part of A that the levels found
        final = KernelMixture(base, [proposal, first],
                              [1.0 - cfg.level_share, cfg.level_share], cfg.alpha)
    return _Explored(base, limit_state, sub, final, n_adapt_evals, rng, deadline, pilot)


def _recentred(base: ZDensity, zi: FloatArray, lwi: FloatArray, cfg: ImportanceSettings,
               rng: np.random.Generator, weighted_centres: bool) -> KernelProposal:
    """The next adaptation round's kernel density: centres resampled by their weights
    from the importance draws ``zi`` inside A (log weights ``lwi``)."""
    ww = np.exp(lwi - lwi.max())
    pick = rng.choice(zi.shape[0], size=min(cfg.n_centres, zi.shape[0]), p=ww / ww.sum())
    # weighted_centres: each resampled centre as often as it was drawn (a part of A
    # the previous q under-covered, whose draws carry large weights, gets more
    # kernels), the bandwidth from the distinct ones; else the distinct centres
    if weighted_centres:
        return KernelProposal(base, zi[pick], cfg.inflate, cfg.alpha, cfg.nu,
                              shape=zi[pick], n_bandwidth=int(np.unique(pick).size))
    return KernelProposal(base, zi[np.unique(pick)], cfg.inflate, cfg.alpha, cfg.nu,
                          shape=zi[pick])


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
                          strata: list[Stratum] | None = None,
                          settings: ImportanceSettings | None = None,
                          budget: StrataBudget | None = None,
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

    ``settings`` (``ImportanceSettings``) hold each stratum's subset-is settings (``n_is``
    the final draws in all), ``budget`` (``StrataBudget``) the figures named above.

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
    cfg = settings or ImportanceSettings()
    bud = budget or StrataBudget()
    strata = make_strata(model) if strata is None else strata
    if not strata:
        raise SamplerError("stratified subset-is: no stratum (the model has no component)")
    if bud.n_is_min < 2 or cfg.n_is < bud.n_is_min:
        raise SamplerError("n_is_min must be >= 2 and n_is >= n_is_min")
    if bud.n_probe < 0 or not 0.0 <= bud.rel_floor < 1.0 or not 0.0 <= bud.adapt_share <= 1.0:
        raise SamplerError("n_probe >= 0, 0 <= rel_floor < 1, 0 <= adapt_share <= 1")
    run = _Stratified(model, limit_state, seed, strata, cfg, bud, t0 + float(cfg.max_seconds))
    run.probe()
    run.find_levels()
    explored = run.adapt()
    out = run.final_draws(explored)
    if keep_runs is not None:
        keep_runs.extend(out)
    return _stratified_result(out, t0, cfg.inflate)


class _Stratified:
    """The steps of one ``stratified_importance`` run over shared state: per stratum its
    evaluations outside its subset result (probes, discarded levels), its levels and its
    run; the running total of the contributions found."""

    def __init__(self, model: CutInGMM, limit_state: LimitState, seed: int,
                 strata: list[Stratum], cfg: ImportanceSettings, budget: StrataBudget,
                 deadline: float) -> None:
        self.model, self.limit_state, self.seed = model, limit_state, seed
        self.strata, self.cfg, self.budget, self.deadline = strata, cfg, budget, deadline
        n = len(strata)
        self.near = np.zeros(n)
        self.extra_evals = [0] * n  # probes and discarded levels (not in the SubsetResult)
        self.runs: list[StratumRun | None] = [None] * n
        self.subs: list[SubsetResult | None] = [None] * n
        self.total = 0.0

    def levels(self, i: int, n: int, floor: float) -> SubsetResult:
        """Stratum i's subset levels with n points per level, down to floor."""
        return subset_simulation(self.model, _in_stratum(self.strata[i], self.limit_state),
                                 _stratum_seed(self.seed, i), n_per_level=n, p0=self.cfg.p0,
                                 max_seconds=max(self.deadline - time.monotonic(), 1e-9),
                                 min_probability=floor, from_normal=self.strata[i].from_normal)

    def explore(self, i: int, sub: SubsetResult, rounds: int) -> _Explored:
        """Stratum i's adaptation from its levels (rounds: 0 keeps the levels' density)."""
        return _explore(self.model, self.limit_state, _stratum_seed(self.seed, i), self.cfg,
                        stratum=self.strata[i], deadline=self.deadline,
                        weighted_centres=self.budget.weighted_centres, sub=sub,
                        adapt_rounds=rounds)

    def probe(self) -> None:
        """1. ``n_probe`` exact draws per stratum: its limit state's lower decile."""
        n_probe = self.budget.n_probe
        if n_probe <= 0:
            return
        for i, st in enumerate(self.strata):
            rng_p = np.random.default_rng([int(self.seed) % (2**32), 11, i])
            gp = np.asarray(_in_stratum(st, self.limit_state)(st.sample_z(int(n_probe), rng_p)))
            self.extra_evals[i] = int(n_probe)
            self.near[i] = float(np.quantile(np.where(np.isfinite(gp), gp, 1e300), 0.1))

    def find_levels(self) -> None:
        """2. Subset levels, the strata nearest the region first (so that the running total
        is known early), each down to a floor relative to what the strata before found."""
        strata = self.strata
        order = sorted(range(len(strata)), key=lambda i: (self.near[i], -strata[i].mass))
        for i in order:
            st = strata[i]
            if time.monotonic() > self.deadline:
                raise SamplerError(f"stratified subset-is: stopped after max_seconds="
                                   f"{self.cfg.max_seconds:g} s exploring stratum {i + 1} of "
                                   f"{len(strata)} ({st.label}); raise max_seconds")
            floor = self.cfg.min_probability
            if self.total > 0 and st.mass > 0:
                floor = min(max(self.cfg.min_probability,
                                self.budget.rel_floor * self.total / st.mass), 0.5)
            sub = self._stratum_levels(i, floor)
            if sub is not None:
                self.subs[i] = sub
                self.total += st.mass * sub.probability
        if not any(sub is not None for sub in self.subs):
            done = [r for r in self.runs if r is not None]
            raise EmptyRegionError(
                f"stratified subset-is: the subset levels reached the region in none of the "
                f"{len(strata)} strata", n_draws=sum(r.n_evaluations for r in done), n_hits=0,
                p_upper=sum(r.stratum.mass * r.p_upper for r in done))

    def _stratum_levels(self, i: int, floor: float) -> SubsetResult | None:
        """Stratum i's levels (the evaluations of discarded attempts added to its extra
        ones), or None when it is bounded, not estimated (its run then says why)."""
        st, cfg, bud, total = self.strata[i], self.cfg, self.budget, self.total
        rerun_evals = 0
        try:
            # once a stratum has reached A, the others' levels only have to show that
            # they are negligible or find A for their kernel density: fewer points
            sub = self.levels(i, cfg.n_per_level if total == 0 else bud.n_per_level_rest,
                              floor)
            if (total > 0 and bud.n_per_level_rest < cfg.n_per_level
                    and st.mass * sub.probability > total):
                # the probes ordered it wrongly: it holds more than all strata before it,
                # so its kernel density needs the full levels (from n_per_level_rest points
                # the final level has too few distinct centres: measured 0.47 and 4e-8 of
                # the reference on `ttc<3 & btn>0.5`, seeds 1014 and 1026)
                rerun_evals = sub.n_evaluations
                sub = self.levels(i, cfg.n_per_level, cfg.min_probability)
        except LevelsNotConvergedError as exc:
            # the levels met A but could not converge on it (a thin region): once more with
            # THIN_RETRY times the points per level, else refuse (the stratum may hold
            # most of P(A); counting it 0 would be silently wrong)
            try:
                sub = self._thin_retry(i, floor)
            except EmptyRegionError as below:
                self.runs[i] = StratumRun(st, None, None, int(exc.n_draws) + int(below.n_draws)
                                          + self.extra_evals[i],
                                          float(below.p_upper) if math.isfinite(below.p_upper)
                                          else floor, str(below).splitlines()[0])
                return None
            rerun_evals += int(exc.n_draws)
        except EmptyRegionError as exc:
            if exc.stalled is not None:
                # the levels stalled (their chains did not move): "empty" bounds nothing
                # here (on `2.9 < ttc < 3 & btn > 0.5` such a stratum held nearly all of
                # P(A)); once more with THIN_RETRY times the points, as above
                rerun_evals += int(exc.n_draws)  # the first attempt's
                try:
                    sub = self._thin_retry(i, floor)
                except EmptyRegionError as below:
                    exc = below
                else:
                    self.extra_evals[i] += rerun_evals
                    return sub
            why = str(exc).splitlines()[0]
            if floor > cfg.min_probability and not rerun_evals:
                why = (f"cut at {floor:.3g} = rel_floor x the running total / pi_s: "
                       f"contribution below {bud.rel_floor:g} of the strata before it ({why})")
            self.runs[i] = StratumRun(st, None, None,
                                      int(exc.n_draws) + self.extra_evals[i] + rerun_evals,
                                      float(exc.p_upper) if math.isfinite(exc.p_upper)
                                      else floor, why)
            return None
        self.extra_evals[i] += rerun_evals  # counted with the probes (not in sub)
        return sub

    def _thin_retry(self, i: int, floor: float) -> SubsetResult:
        """Stratum i's levels once more with ``THIN_RETRY`` times the points; levels that
        do not converge again are refused (``_unconverged``)."""
        n = THIN_RETRY * self.cfg.n_per_level
        try:
            return self.levels(i, n, floor)
        except LevelsNotConvergedError as again:
            raise _unconverged(self.strata[i], again, n) from None

    def adapt(self) -> dict[int, _Explored]:
        """3. Adaptation where the contribution is worth it (``adapt_share``); a stratum
        whose final level is too thin for a kernel density is bounded when negligible,
        else its levels are re-run with more points."""
        explored: dict[int, _Explored] = {}
        cfg, bud, total = self.cfg, self.budget, self.total
        for i, found in enumerate(self.subs):
            if found is None:
                continue
            st, sub = self.strata[i], found
            big = total > 0 and st.mass * sub.probability >= bud.adapt_share * total
            rounds = cfg.adapt_rounds if big else 0
            try:
                ex = self.explore(i, sub, rounds)
            except EmptyRegionError as exc:
                if st.mass * sub.probability < bud.rel_floor * total:  # negligible: bounded
                    self.runs[i] = StratumRun(st, None, None,
                                              sub.n_evaluations + self.extra_evals[i],
                                              sub.probability, str(exc).splitlines()[0])
                    continue
                # too few distinct points in a stratum that matters (a thin region: the
                # final level's chains barely moved): its levels once more with more points
                self.extra_evals[i] += sub.n_evaluations
                try:
                    sub = self.levels(i, THIN_RETRY * cfg.n_per_level, cfg.min_probability)
                    ex = self.explore(i, sub, rounds)
                except (EmptyRegionError, LevelsNotConvergedError) as again:
                    raise _unconverged(st, again, THIN_RETRY * cfg.n_per_level) from None
            explored[i] = ex
            self.runs[i] = StratumRun(st, None, ex.sub,
                                      self.extra_evals[i] + ex.sub.n_evaluations + ex.n_adapt)
        if not explored:
            done = [r for r in self.runs if r is not None]
            raise EmptyRegionError(
                "stratified subset-is: no stratum's final subset level held enough distinct "
                "points inside the region for an importance density; raise n_per_level",
                n_draws=sum(r.n_evaluations for r in done), n_hits=0)
        return explored

    def final_draws(self, explored: dict[int, _Explored]) -> list[StratumRun]:
        """4. The final importance draws, ``n_is`` in all, by estimated contribution (at
        least ``n_is_min`` each); the runs of every stratum."""
        keys = list(explored)
        contrib = np.array([self.strata[i].mass * max(explored[i].pilot[0], 0.0)
                            for i in keys])
        share = (contrib / contrib.sum() if contrib.sum() > 0
                 else np.full(len(keys), 1 / len(keys)))
        for i, sh in zip(keys, share, strict=True):
            ex_i = explored[i]
            stage = ImportanceStage(ex_i.base, ex_i.limit_state, ex_i.proposal, self.deadline,
                                    self.cfg.max_seconds)
            stage.add(max(int(self.budget.n_is_min), round(self.cfg.n_is * float(sh))),
                      ex_i.rng)
            run_i = self.runs[i]
            assert run_i is not None
            run_i.stage = stage
        return [r for r in self.runs if r is not None]


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


def _stratum_info(r: StratumRun, ps: float, se: float) -> dict[str, Any]:
    """One stratum's figures in the result's ``proposal["strata"]`` (``ps``, ``se``: its
    estimate and standard error)."""
    pi = r.stratum.mass
    info: dict[str, Any] = {"stratum": r.stratum.label, "mass": pi, "p": ps,
                            "cov": se / ps if ps > 0 else None,
                            "contribution": pi * ps,
                            "n_evaluations": r.n_evaluations + (r.stage.n if r.stage else 0)}
    if r.sub is not None:
        info["subset_levels"] = len(r.sub.thresholds)
    else:
        info["empty_upper"] = pi * r.p_upper
        info["empty_reason"] = r.note
    if r.stage is not None:
        inside = np.isfinite(r.stage.log_w)
        info["n_is"] = r.stage.n
        info["level_share"] = _level_share(r.stage.proposal)
        info["n_hits"] = int(inside.sum())
    return info


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
        strata.append(_stratum_info(r, ps, se))
        if r.sub is not None:
            n_sub += r.sub.n_evaluations
            n_adapt += r.n_evaluations - r.sub.n_evaluations
        else:
            n_sub += r.n_evaluations
        if r.stage is not None:
            n_is += r.stage.n
            lw = r.stage.log_w
            inside = np.isfinite(lw)
            n_hits += int(inside.sum())
            zs.append(r.stage.z[inside])
            # weights relative to the whole model, on the plain result's scale:
            # P = sum(exp(log_w)) / n_is as there (each stratum's draws estimate pi_s P_s:
            # pi_s p_s / q_s / n_s per draw, times the total n_is)
            lws.append(lw[inside] + math.log(pi) - math.log(r.stage.n))
            if r.sub is not None and (best is None or pi * ps > best[0]):
                best = (pi * ps, r.sub)
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


@dataclass(frozen=True)
class StrataSettings:
    """Whether and how ``SubsetISSampler`` stratifies (``stratified_importance``).

    Attributes
    ----------
    stratify : {"auto", "always", "never"}
        ``always``: one subset-is per stratum of the model (component x cut-in side, or
        component x envelope, ``envelope``); ``never``: one subset-is on the whole model;
        ``auto``: see ``STRATIFY_AUTO``.
    per_level, n_adapt, n_is_min :
        The stratified run's ``n_per_level``, ``n_adapt`` and ``n_is_min``
        (``stratified_importance``; ``n_is`` is the sampler's).
    split_side : bool
        Split each component by the cut-in side (``make_strata``).
    weighted_centres : bool
        ``StrataBudget.weighted_centres``.
    envelope : bool
        Stratify inside the region's half-space envelope when it has one (component x S,
        ``SubsetISSampler._strata``): the levels then only go down to P(A | S), and nothing
        outside S is simulated (measured in ``docs/sampler.md``).
    env_n_adapt : int
        ``n_adapt`` of a run stratified inside the envelope (its levels cost less, and the
        adaptation needs more draws there: on a closed-form region the reported CoV was
        27 % low with 1,500 and right with 2,000; on the TNO envelope regions 2,000 kept
        0.95-0.97 of the seeds in 2 CoV, and 3,000 cost more evaluations for no better
        coverage; ``docs/sampler.md``).
    """

    stratify: str = "auto"
    per_level: int = 1000
    n_adapt: int = 1500
    n_is_min: int = 300
    split_side: bool = True
    weighted_centres: bool = True
    envelope: bool = True
    env_n_adapt: int = 2000

    def __post_init__(self) -> None:
        if self.stratify not in ("auto", "always", "never"):
            raise SamplerError(f"stratify: expected auto, always or never, got "
                               f"{self.stratify!r}")


@dataclass(frozen=True)
class ChainSettings:
    """The independence chains that turn subset-is's importance draws into samples.

    Attributes
    ----------
    ess_target : float
        Draw more proposals until the chains' effective sample size is at least
        ``ess_target * n`` (when the budget is nearly spent first: a warning in the
        diagnostics instead).
    n_chains : int
        Independence chains the proposals are dealt to.
    """

    ess_target: float = 0.25
    n_chains: int = 4


#: ``SubsetISSampler``'s settings by their flat names (``settings()``, ``from_settings``):
#: name -> (settings object, field, type)
_FLAT: dict[str, tuple[str, str, type]] = {
    "n_per_level": ("importance", "n_per_level", int), "n_is": ("importance", "n_is", int),
    "alpha": ("importance", "alpha", float), "inflate": ("importance", "inflate", float),
    "n_adapt": ("importance", "n_adapt", int),
    "adapt_rounds": ("importance", "adapt_rounds", int),
    "n_centres": ("importance", "n_centres", int),
    "max_seconds": ("importance", "max_seconds", float),
    "min_probability": ("importance", "min_probability", float),
    "ess_target": ("chains", "ess_target", float), "n_chains": ("chains", "n_chains", int),
    "stratify": ("stratification", "stratify", str),
    "strat_per_level": ("stratification", "per_level", int),
    "strat_n_adapt": ("stratification", "n_adapt", int),
    "strat_n_is_min": ("stratification", "n_is_min", int),
    "strat_split_side": ("stratification", "split_side", bool),
    "strat_weighted_centres": ("stratification", "weighted_centres", bool),
    "strat_envelope": ("stratification", "envelope", bool),
    "strat_env_n_adapt": ("stratification", "env_n_adapt", int),
    "level_share": ("importance", "level_share", float),
}


class SubsetISSampler(Sampler):
    """Subset levels, importance sampling for P(A), an independence chain for the samples.

    Parameters
    ----------
    importance : ImportanceSettings, optional
        The subset-is run (``subset_importance``; per stratum in the stratified one, whose
        ``n_per_level`` and ``n_adapt`` come from ``stratification``): levels, proposal,
        adaptation, the time budget of the whole run (exceeded -> ``SamplerError``) and the
        smallest mass the levels go down to (below: ``EmptyRegionError``).
    stratification : StrataSettings, optional
    chains : ChainSettings, optional

    ``from_settings(**flat)`` builds one from the flat names ``settings()`` records (e.g.
    ``strat_envelope=False``; what ``rare_probability`` passes on).
    """

    name = "subset-is"

    def __init__(self, importance: ImportanceSettings | None = None,
                 stratification: StrataSettings | None = None,
                 chains: ChainSettings | None = None) -> None:
        self.importance = importance or ImportanceSettings()
        self.stratification = stratification or StrataSettings()
        self.chains = chains or ChainSettings()

    @classmethod
    def from_settings(cls, **flat: Any) -> SubsetISSampler:
        """A sampler from flat settings (the names of ``settings()``: ``n_is``, ``alpha``,
        ``stratify``, ``strat_envelope``, ...); the others keep their defaults."""
        unknown = sorted(set(flat) - set(_FLAT))
        if unknown:
            raise SamplerError(f"subset-is: unknown setting(s) {', '.join(unknown)}; valid: "
                               f"{', '.join(_FLAT)}")
        parts: dict[str, dict[str, Any]] = {"importance": {}, "stratification": {},
                                            "chains": {}}
        for key, value in flat.items():
            part, name, kind = _FLAT[key]
            parts[part][name] = value if kind is str else kind(value)
        return cls(ImportanceSettings(**parts["importance"]),
                   StrataSettings(**parts["stratification"]), ChainSettings(**parts["chains"]))

    def settings(self) -> dict[str, Any]:
        """The flat settings (``from_settings`` takes them back)."""
        return {"name": self.name, **{key: getattr(getattr(self, part), name)
                                      for key, (part, name, _) in _FLAT.items()}}

    def _limit_state(self, problem: Problem, rng: np.random.Generator) -> LimitState:
        limit_state = region_limit_state(problem.model, problem.region, rng)

        def counted(z: FloatArray) -> FloatArray:
            problem.n_evals += z.shape[0]
            return limit_state(z)

        return counted

    def _strata(self, problem: Problem) -> tuple[list[Stratum], bool]:
        """The strata of a stratified run and whether they lie inside an envelope: with
        ``StrataSettings.envelope`` and a region that has a half-space envelope S
        (``sampler.methods.envelope``, e.g. from ``ttc<3``), component x S (every stratum inside
        S, which holds the region: each P_s(A) is conditional on S, and no simulation is
        spent outside it); else component x cut-in side."""
        if self.stratification.envelope:
            env = find_envelope(problem.model, problem.region)
            if env is not None:
                return halfspace_strata(problem.model, env.a, env.b, env.source), True
        return make_strata(problem.model, self.stratification.split_side), False

    def _stratified(self, problem: Problem) -> bool:
        if self.stratification.stratify == "always":
            return True
        if self.stratification.stratify == "never":
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
        if self._stratified(problem):
            strata, inside_envelope = self._strata(problem)
            st = self.stratification
            per_stratum = replace(self.importance, n_per_level=st.per_level,
                                  n_adapt=st.env_n_adapt if inside_envelope else st.n_adapt)
            budget = StrataBudget(n_is_min=st.n_is_min, weighted_centres=st.weighted_centres)
            return stratified_importance(problem.model, limit_state, seed, strata=strata,
                                         settings=per_stratum, budget=budget,
                                         keep_runs=keep_runs)
        return subset_importance(problem.model, limit_state, seed, self.importance,
                                 keep_stage=keep_stage)

    def _chains(self, stage: ImportanceStage, n: int, rng: np.random.Generator,
                t_start: float, warnings: list[str], what: str
                ) -> tuple[FloatArray, dict[str, Any]]:
        """``n`` samples of the stage's restricted law from independence chains over its
        draws (more draws until the chains' ESS reaches ``ess_target * n``)."""
        while True:
            states, acc = independence_chain(stage.log_w, rng, self.chains.n_chains)
            zs = stage.z
            tau = integrated_time(zs[states])  # chain (steps, chains, d)
            tau_max = float(tau.max())
            burn = min(math.ceil(2 * tau_max), states.shape[0] // 2)
            post = states[burn:]
            ess = post.size / tau_max
            if ess >= self.chains.ess_target * n:
                break
            if time.monotonic() - t_start > 0.8 * self.importance.max_seconds:
                warnings.append(f"{what}time budget nearly spent with ESS {ess:.0f} < "
                                f"{self.chains.ess_target * n:.0f}: the samples are more "
                                "correlated than asked")
                break
            need = self.chains.ess_target * n / max(ess, 1.0) * stage.n - stage.n
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
            res = _result(stages[0], res.subset, t_start, res.n_adapt, self.importance.inflate)
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
            res = _stratified_result(runs, t_start, self.importance.inflate)
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
                "n_chains": self.chains.n_chains, **diag, "warnings": warnings}
        return Draw(z=np.ascontiguousarray(z), method=self.name, diagnostics=diag,
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits, subset=res)

    def estimate_p(self, run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
        return estimate_from_levels(run, pilot, drawn)

    def estimate_alone(self, run: Run, pilot: Pilot) -> PRegion:
        """P(A) without samples: a subset-is run (``run``), overruled by the pilot's exact
        draws when it contradicts them (``PRegionEstimator.from_subset``)."""
        run.starting("subset-is (rare-event estimate)")
        return run.estimator.from_subset(run.problem, self.run(run.problem, run.rng),
                                         run.bounds, pilot)

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        d = diagnostics
        r = d["subset_is"]
        return [f"subset-is: {r['n_evaluations']} evaluations ({r['subset']['levels']} "
                f"subset levels), CoV {r['cov']:.3f}; independence chains: "
                f"acceptance {d['acceptance_mean']:.2f}, tau {d['tau_max']:.1f}, "
                f"ESS {d['ess']:.0f}", *d.get("warnings", [])]


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
    return SubsetISSampler.from_settings(**settings).run(problem, np.random.default_rng(seed))
