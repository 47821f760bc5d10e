"""Subset simulation (Au & Beck 2001) for rare regions, on OpenTURNS' ``SubsetSampling``.

A region A is written as a limit state ``g(z) <= 0`` (``LimitState``: z-space rows (n, d)
-> g of shape (n,), vectorised). Subset simulation estimates ``P(g <= 0)`` as a product of
conditional probabilities of nested levels ``g <= b_1``, ``g <= b_2``, ..., ``g <= 0``:
the thresholds ``b_j`` are the ``p0``-quantiles of the current level's samples (adaptive,
``p0 = 0.1``), and each level's samples are made by Markov chains (OpenTURNS' modified
Metropolis, component-wise, uniform proposal of half-width ``proposal_range``) started from
the previous level's samples inside it. The final level's samples inside A are draws of
(approximately) the model restricted to A: the sample set.

The glue written here (everything else is OpenTURNS):

* the standard-normal parametrisation of the mixture. OpenTURNS' subset sampling works in
  standard normal space; the mixture is not a transform of a Gaussian, so the input is a
  standard normal vector ``u`` of dimension ``d + 1``: ``u[0]`` picks the component
  (``Phi(u[0])`` through the cumulative weights) and ``z = mean_k + L_k u[1:]``. The image
  of ``N(0, I)`` under this map is exactly the mixture, so ``P(g(T(u)) <= 0) = P(A)``.
* the coefficient of variation. OpenTURNS reports per level the chain-correlation factor
  ``gamma_j`` of Au & Beck (2001, eq. 27); we combine ``delta_j^2 = (1 - p_j) / (N p_j)
  (1 + gamma_j)`` (``gamma_0 = 0``: level 0 is plain Monte Carlo, which OpenTURNS' own
  per-step figure leaves out) into ``cov = sqrt(sum delta_j^2)`` (levels independent, Au &
  Beck's estimate) and ``cov_upper = sum delta_j`` (levels fully correlated, their upper
  bound). The P(A) interval uses ``cov_upper`` (see ``sampler.methods.probability``).
* a region's limit state (``region_limit_state``): the largest of the constraints'
  margins, each scaled by a robust spread of its quantity under the model, and +inf
  outside the physical bounds.

Why OpenTURNS and not emcee here: the levels, the conditional-sampling chains and the
correlation-aware CoV are the library's, well tested; the project's emcee machinery would
need all of them written by hand. Measured with seeded repetitions (``tests/sampler/
test_subset.py``, ``benchmarks/bench_rare.py``): unbiased, CoV somewhat optimistic (the
levels are correlated), hence the interval on ``cov_upper``. One run of OpenTURNS with a
single outer iteration (``MaximumOuterSampling = 1``) was biased (factor ~0.6 at 1e-5), so
every level is made as ``1 / p0`` blocks of ``N p0`` points (one vectorised limit-state call
per block).

Determinism: OpenTURNS draws from one process-wide generator; it is seeded from our
Generator and used under a lock, so the same seed gives the same result.
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from sampler.errors import EmptyRegionError, LevelsNotConvergedError, SamplerError
from sampler.methods.problem import Draw, FloatArray, Pilot, Problem, ProgressFn, Run, Sampler
from sampler.model.gmm import CutInGMM
from sampler.model.support import support_margin
from sampler.region.constraints import OPERATORS, Region
from sampler.region.criticality import CRITICALITY_QUANTITIES, criticality_quantities

if TYPE_CHECKING:  # annotations only
    from sampler.methods.probability import PRegion

__all__ = ["LimitState", "SubsetResult", "SubsetSampler", "region_limit_state",
           "subset_simulation"]

#: vectorised limit state in the model's z-space: rows (n, d) -> g (n,); A is g <= 0
LimitState = Callable[[FloatArray], FloatArray]

_OT_LOCK = threading.Lock()
#: limit states treat rows farther than this (Mahalanobis) from every component as outside
#: A: the mixture's mass there is below the chi-square (d = 8) tail at 15^2, ~1e-44
R_MAX = 15.0
_BIG = 1e300  # stands for +inf (outside the bounds, NaN quantities) in OpenTURNS' quantiles


class _Stop(Exception):
    """Raised inside the limit state when the time budget is spent."""


@dataclass(frozen=True)
class SubsetResult:
    """Outcome of one subset simulation.

    Attributes
    ----------
    probability : float
        Estimate of ``P(g <= 0)`` under the model.
    cov, cov_upper : float
        Coefficient of variation (independent levels) and its upper bound (fully correlated
        levels), both with the chains' correlation factors.
    n_evaluations : int
        Limit-state evaluations made.
    thresholds, conditional, gamma, delta : list of float
        Per level: threshold b_j, conditional probability p_j, chain-correlation factor,
        the level's CoV delta_j.
    z : ndarray (m, d)
        The final level's samples inside A (g <= 0), z-space, in chain order.
    n_per_level : int
    seconds : float
    """

    probability: float
    cov: float
    cov_upper: float
    n_evaluations: int
    thresholds: list[float]
    conditional: list[float]
    gamma: list[float]
    delta: list[float]
    z: FloatArray = field(repr=False)
    n_per_level: int = 0
    seconds: float = 0.0

    def summary(self) -> dict[str, Any]:
        """JSON-able figures (without the samples)."""
        return {"probability": self.probability, "cov": self.cov, "cov_upper": self.cov_upper,
                "n_evaluations": self.n_evaluations, "levels": len(self.thresholds),
                "thresholds": self.thresholds, "conditional": self.conditional,
                "gamma": self.gamma, "delta": self.delta, "n_per_level": self.n_per_level,
                "n_final": int(self.z.shape[0]), "seconds": self.seconds}


def mixture_from_normal(model: CutInGMM, u: FloatArray) -> FloatArray:
    """The map T: standard normal (n, d + 1) -> mixture z-space (n, d) (module docstring)."""
    labels = np.searchsorted(model.weights_cdf_, stats.norm.cdf(u[:, 0]), side="right")
    np.minimum(labels, model.n_components_ - 1, out=labels)
    e = u[:, 1:]
    z = np.empty_like(e)
    for k in range(model.n_components_):
        idx = labels == k
        z[idx] = model.means_[k] + e[idx] @ model.cholesky_[k].T
    return z


def subset_simulation(model: CutInGMM, limit_state: LimitState, seed: int, *,
                      n_per_level: int = 2000, p0: float = 0.1, proposal_range: float = 2.0,
                      max_seconds: float = 120.0, min_probability: float = 1e-14,
                      from_normal: Callable[[FloatArray], FloatArray] | None = None
                      ) -> SubsetResult:
    """Estimate ``P(limit_state(z) <= 0)`` under the model by subset simulation.

    ``from_normal`` replaces the map from standard normal ``(n, d + 1)`` to z-space (default
    ``mixture_from_normal``: the whole mixture); the probability is then under the image of
    ``N(0, I)`` by that map (``sampler.methods.strata``: one component, optionally restricted to a
    half-space).

    Raises
    ------
    SamplerError
        Bad settings, or the time budget ``max_seconds`` was spent (the message says how far
        it got).
    EmptyRegionError
        The levels reached ``min_probability`` without reaching g <= 0 (the region holds
        less mass than that; the upper bound is in the error).
    """
    import openturns as ot

    model.check_fitted()
    plan = _Plan.checked(n_per_level, p0, proposal_range, max_seconds, min_probability)
    d = model.n_features
    to_z: Callable[[FloatArray], FloatArray] = (
        from_normal if from_normal is not None
        else (lambda u: mixture_from_normal(model, u)))
    budget = _Budget(limit_state, to_z, deadline=time.monotonic() + float(max_seconds),
                     max_evals=(plan.max_levels + 1) * plan.blocks * plan.chains)

    fun = ot.PythonFunction(d + 1, 1, func_sample=budget)
    event = ot.ThresholdEvent(ot.CompositeRandomVector(fun, ot.RandomVector(ot.Normal(d + 1))),
                              ot.LessOrEqual(), 0.0)
    t0 = time.monotonic()
    steps, thresholds, cumulative, gamma, u_final = _run_levels(event, seed, plan, budget)
    if thresholds[-1] > 0:
        raise EmptyRegionError(
            f"subset simulation reached P = {cumulative[-1]:.3g} after {steps} levels "
            f"(min_probability={min_probability:g}) with the limit state still above 0 "
            f"(threshold {thresholds[-1]:.3g}): the region holds less mass than that"
            + _stall_note(_stalled(thresholds)),
            n_draws=budget.evals, n_hits=0, p_upper=cumulative[-1],
            stalled=_stalled(thresholds))
    return _levels_result(cumulative, thresholds, gamma, steps, plan.blocks * plan.chains,
                          n_evaluations=budget.evals,
                          z=to_z(u_final) if u_final.size else np.zeros((0, d)),
                          seconds=time.monotonic() - t0)


@dataclass(frozen=True)
class _Plan:
    """The checked settings of one subset simulation and the level layout they give."""

    p0: float
    proposal_range: float
    max_seconds: float
    min_probability: float
    chains: int  # per block: N p0
    blocks: int  # per level: 1 / p0
    #: levels needed to go below min_probability, plus slack: a region that the levels
    #: cannot reach (empty, or g stuck above 0) ends there instead of running on
    max_levels: int

    @classmethod
    def checked(cls, n_per_level: int, p0: float, proposal_range: float, max_seconds: float,
                min_probability: float) -> _Plan:
        """The plan of ``subset_simulation``'s settings; SamplerError when one is bad."""
        if not 0.0 < p0 < 0.5:
            raise SamplerError(f"p0: must be in (0, 0.5), got {p0!r}")
        chains = math.ceil(n_per_level * p0)
        blocks = round(1.0 / p0)
        if chains < 10:
            raise SamplerError(f"n_per_level: need at least {math.ceil(10 / p0)}, "
                               f"got {n_per_level}")
        if not (max_seconds > 0 and proposal_range > 0 and 0 < min_probability < 1):
            raise SamplerError("max_seconds, proposal_range and min_probability must be "
                               "positive (min_probability < 1)")
        max_levels = math.ceil(math.log(min_probability) / math.log(p0)) + 5
        return cls(p0, proposal_range, max_seconds, min_probability, chains, blocks,
                   max_levels)


def _run_levels(event: Any, seed: int, plan: _Plan, budget: _Budget
                ) -> tuple[int, list[float], list[float], list[float], FloatArray]:
    """OpenTURNS' subset sampling of ``event``, seeded from ``seed``, under the lock: the
    number of levels, per level the threshold, the cumulative probability and the chains'
    correlation factor, and the last level's standard normal points inside the event.
    A run OpenTURNS stops becomes the error ``_failure`` makes of it."""
    import openturns as ot

    with _OT_LOCK:
        ot.RandomGenerator.SetSeed(int(seed) % (2**31 - 1))
        algo = ot.SubsetSampling(event)
        algo.setConditionalProbability(float(plan.p0))
        algo.setMaximumOuterSampling(plan.blocks)
        algo.setBlockSize(plan.chains)
        algo.setProposalRange(float(plan.proposal_range))
        algo.setMinimumProbability(float(plan.min_probability))
        algo.setKeepSample(True)
        try:
            algo.run()
        except RuntimeError as exc:
            raise _failure(exc, algo, budget, max_seconds=plan.max_seconds,
                           max_levels=plan.max_levels,
                           min_probability=plan.min_probability) from None
        except TypeError as exc:
            # OpenTURNS 1.27 refuses to finish when the last level holds every sample
            # (conditional probability 1: zero variance, gamma NaN); the levels are complete
            # and the estimate is the product so far, read from the per-step figures below
            if "variance estimate" not in str(exc):
                raise
        steps = int(algo.getStepsNumber())
        thresholds = [float(b) for b in algo.getThresholdPerStep()]
        cumulative = [float(p) for p in algo.getProbabilityEstimatePerStep()]
        gamma = [float(x) if math.isfinite(x) else 0.0 for x in algo.getGammaPerStep()]
        u_final = np.asarray(algo.getInputSample(steps - 1, ot.SubsetSampling.EVENT1),
                             dtype=np.float64)
    return steps, thresholds, cumulative, gamma, u_final


@dataclass
class _Budget:
    """The limit state as OpenTURNS calls it, on standard normal rows: counts the
    evaluations, the rows inside and the lowest g, and stops the run (``_Stop``) past the
    deadline (``stopped``) or the evaluation budget (``exhausted``)."""

    limit_state: LimitState
    to_z: Callable[[FloatArray], FloatArray]
    deadline: float
    max_evals: int
    evals: int = 0
    best: float = math.inf
    inside: int = 0
    stopped: bool = False
    exhausted: bool = False

    def __call__(self, u_sample: Any) -> Any:
        if time.monotonic() > self.deadline:
            self.stopped = True
            raise _Stop
        if self.evals >= self.max_evals:
            self.exhausted = True
            raise _Stop
        u = np.asarray(u_sample, dtype=np.float64)
        g = np.asarray(self.limit_state(self.to_z(u)), dtype=np.float64)
        self.evals += u.shape[0]
        g = np.where(np.isfinite(g), g, _BIG)
        if g.size:
            self.best = min(self.best, float(g.min()))
            self.inside += int(np.count_nonzero(g <= 0))
        return g[:, None]


def _failure(exc: RuntimeError, algo: Any, budget: _Budget, *, max_seconds: float,
             max_levels: int, min_probability: float) -> Exception:
    """What a run OpenTURNS stopped with ``exc`` means: out of time, levels that met the
    region but did not converge on it, a region not reached (empty or below
    ``min_probability``), or another failure."""
    if budget.stopped:
        return SamplerError(
            f"subset simulation: stopped after max_seconds={max_seconds:g} s "
            f"({budget.evals} evaluations, lowest g so far {budget.best:.3g}); "
            "raise max_seconds or n_per_level's budget")
    stall = _stalled([float(b) for b in algo.getThresholdPerStep()])
    if budget.exhausted:
        if budget.inside > 0:
            # rows inside A were met, but the thresholds never reached 0: the
            # levels' chains barely move (a thin region); their product of
            # conditional probabilities is then no bound on P(A)
            return LevelsNotConvergedError(
                f"subset simulation met the region ({budget.inside} evaluated rows "
                f"inside it) but its levels did not converge on it in {max_levels} "
                f"levels ({budget.evals} evaluations): the region is probably too "
                "thin for the levels' Markov chains (e.g. a narrow ttc band)",
                n_draws=budget.evals, n_hits=budget.inside)
        return EmptyRegionError(
            f"subset simulation did not reach the region in {max_levels} levels "
            f"({budget.evals} evaluations, lowest g {budget.best:.3g} > 0): it is "
            f"empty or holds less than min_probability={min_probability:g}"
            + _stall_note(stall),
            n_draws=budget.evals, n_hits=0, p_upper=min_probability, stalled=stall)
    if "too small" not in str(exc):
        return SamplerError(f"subset simulation failed: {str(exc).splitlines()[0]}")
    cumulative = [float(p) for p in algo.getProbabilityEstimatePerStep()]
    p_up = min([*cumulative, 1.0])
    return EmptyRegionError(
        f"subset simulation went below min_probability={min_probability:g} "
        f"(P = {p_up:.3g} after {algo.getStepsNumber()} levels) without reaching "
        "the region: it holds less mass than that" + _stall_note(stall),
        n_draws=budget.evals, n_hits=0, p_upper=p_up, stalled=stall)


def _levels_result(cumulative: list[float], thresholds: list[float], gamma: list[float],
                   steps: int, n: int, *, n_evaluations: int, z: FloatArray,
                   seconds: float) -> SubsetResult:
    """The estimate of converged levels: the product of the levels' conditional
    probabilities and its coefficient of variation (Au & Beck 2001; delta_j per level)."""
    conditional = [cumulative[0]] + [cumulative[j] / cumulative[j - 1] if cumulative[j - 1] > 0
                                     else 0.0 for j in range(1, steps)]
    gamma = [0.0, *gamma[1:steps]]
    delta = [math.sqrt((1 - p) / (n * p) * (1 + g)) if p > 0 else math.inf
             for p, g in zip(conditional, gamma, strict=True)]
    return SubsetResult(
        probability=cumulative[-1],
        cov=float(math.sqrt(sum(x * x for x in delta))),
        cov_upper=float(sum(delta)),
        n_evaluations=n_evaluations,
        thresholds=thresholds, conditional=conditional, gamma=gamma, delta=delta,
        z=z, n_per_level=n, seconds=seconds)


#: this many levels in a row with one and the same threshold: the levels have stalled
STALL_LEVELS = 3


def _stalled(thresholds: list[float]) -> float | None:
    """The threshold that ``STALL_LEVELS`` consecutive levels (after the first) share
    exactly, or None. A level's threshold is the p0-quantile of its points; it repeats
    only when the chains' lowest points are copies, i.e. the chains did not move (on
    `2.9 < ttc < 3 & btn > 0.5` 200-point levels repeated 0.1513 nine times and were
    then read as "empty below 1e-14" though the stratum holds nearly all of P(A)). Also
    what an empty region's levels do once their chains sit at g's lowest value above 0.
    ``EmptyRegionError.stalled`` carries it."""
    run = 1
    for j in range(2, len(thresholds)):
        run = run + 1 if thresholds[j] == thresholds[j - 1] else 1
        if run >= STALL_LEVELS:
            return thresholds[j]
    return None


def _stall_note(stall: float | None) -> str:
    if stall is None:
        return ""
    return (f"; but its levels stalled (threshold {stall:.4g} for {STALL_LEVELS} or more "
            "levels in a row: the chains did not move), so this is no reliable bound (a "
            "region too thin for the chains, or g's lowest value above 0)")


def _near(model: CutInGMM, z: FloatArray) -> NDArray[np.bool_]:
    """Rows with finite coordinates within ``R_MAX`` Mahalanobis units of a component."""
    finite = np.asarray(np.isfinite(z).all(axis=1), dtype=bool)
    zz = np.where(finite[:, None], z, 0.0)
    near = np.zeros(z.shape[0], dtype=bool)
    for k in range(model.n_components_):
        y = np.linalg.solve(model.cholesky_[k], (zz - model.means_[k]).T)
        near |= np.einsum("ij,ij->j", y, y) <= R_MAX**2
    return near & finite


def _margin_scale(values: FloatArray) -> float:
    v = values[np.isfinite(values)]
    if v.size < 2:
        return 1.0
    q25, q75 = np.percentile(v, [25.0, 75.0])
    s = float(q75 - q25) / 1.349
    if not s > 0:
        s = float(np.std(v))
    return s if s > 0 else 1.0


#: quantities that hold one value over much of the model (the constant-speed ego never
#: reaches the cutter): that value, and for ``ttr_true`` (+inf there) the finite stand-in
#: the flat rows' margin starts from (s; finite TTRs of the data stay well below it)
FLAT_VALUES: dict[str, float] = {"btn": 0.0, "a_req": 0.0, "r157_impact_speed": 0.0,
                                 "ttr_true": math.inf}
_TTR_FLAT_STANDIN = 10.0
#: horizon (s) of the closeness proxy ``gap - horizon * dv`` that orders the flat rows
FLAT_PROXY_HORIZON = 3.0


def ttc_margin(gap: FloatArray, dv: FloatArray, op: str, value: float) -> FloatArray:
    """A continuous margin of ``ttc op value`` (``ttc = gap / dv`` for ``dv > 0``, else
    +inf), negative inside, positive outside (0 on the threshold): ``gap - value * dv``
    for ``<``/``<=`` (``value * dv - gap`` for ``>``/``>=``) where ``dv > 0`` (there
    ``gap / dv < value`` is ``gap - value dv < 0``); where ``dv <= 0`` (TTC +inf: outside
    ``<``, inside ``>``) the same expression, pushed to the right sign when it has the
    wrong one. ``ttc`` itself is +inf for every non-closing cut-in (most of the model), a
    flat limit state on which subset levels cannot progress; this one is not."""
    sgn = 1.0 if op in ("<", "<=") else -1.0
    with np.errstate(invalid="ignore"):
        m = sgn * (np.asarray(gap, dtype=np.float64) - value * np.asarray(dv, dtype=np.float64))
        tiny = float(np.finfo(np.float64).tiny)
        closing = np.asarray(dv) > 0
        infinite_inside = sgn < 0  # ttc = +inf satisfies > and >=
        fix = np.maximum(m, tiny) if not infinite_inside else np.minimum(m, -tiny)
        out = np.where(closing | np.isnan(m), m, fix)
    return np.asarray(out, dtype=np.float64)


def region_limit_state(model: CutInGMM, region: Region, rng: np.random.Generator,
                       n_scale: int = 4096) -> LimitState:
    """A limit state whose set ``g <= 0`` is the region (a strict constraint's threshold
    gets the smallest positive margin, so it lies outside, as in ``Region.contains``).

    ``g = max_c m_c``, the constraints' margins ``(q - v) / s_c`` for ``q < v`` (``q <= v``)
    and ``(v - q) / s_c`` for ``q > v`` (``q >= v``), ``s_c`` the quantity's robust spread
    (IQR / 1.349) over ``n_scale`` model draws (so no constraint dominates the levels by
    its unit; 1 when the constraints name one quantity: then the scale changes nothing and
    costs no simulation); +inf outside the physical bounds (when on; such rows are not
    simulated), where a quantity is NaN, and farther than ``R_MAX`` = 15 Mahalanobis
    units from every component (mass ~1e-44 for d = 8; importance densities' tails
    reach such rows, whose closed-loop simulation would be meaningless and huge).

    Flat quantities get continuous margins (the same set ``g <= 0``), so that subset levels
    can progress through the large parts of the model where the quantity does not change
    (a level whose ``p0``-quantile falls on a tie cannot shrink):

    * ``ttc``: ``ttc_margin`` (``gap - v dv``, scaled by its spread), not ``ttc - v``;
    * ``btn``, ``a_req``, ``r157_impact_speed`` at 0 and ``ttr_true`` at +inf
      (``FLAT_VALUES``: the constant-speed ego never reaches the cutter) where that value
      is outside the constraint: the margin of the flat value (+10 s for ``ttr_true``)
      plus ``softplus((gap - 3 s dv) / s_h)`` (> 0, so still outside), which ranks the flat
      rows by how close the cutter is to being reached.

    **Layered** when the region has both kinematic constraints (``ttc``, ``thw``, model
    features: no simulation) and criticality ones (``btn``, ``ttr_true``, ...: one
    closed-loop simulation per row): a row outside the kinematic ones gets ``LAYER`` + their
    largest margin and is not simulated; a row inside them gets the largest criticality
    margin (clipped to ``LAYER``). The set ``g <= 0`` is the same; the levels first close
    in on the kinematic part (often a large share of a stratum inside its envelope:
    ``ttc<3`` holds 38 % of its envelope) and then rank only rows inside it, and neither
    the levels nor the importance draws simulate a row the kinematic constraints already
    exclude. Only several criticality quantities need simulated draws for their scales.
    """
    cons = region.constraints
    if not cons:
        raise SamplerError("subset simulation needs at least one constraint (the region is "
                           "the whole model)")
    g = _RegionMargins.of(model, region.bind(model))  # bound: its model quantities
    g.fit_scales(rng, int(n_scale))
    return g


_TINY = float(np.finfo(np.float64).tiny)


@dataclass
class _RegionMargins:
    """``region_limit_state``'s limit state, in its steps: the quantities a row needs, each
    constraint's margin (scaled, continuous where the quantity is flat), the largest of a
    group, and ``__call__`` = g (layered or not)."""

    model: CutInGMM
    region: Region
    other: list[str]  # the quantities besides the criticality ones (and ttc)
    crit: list[str]  # the criticality quantities the constraints name
    flat: bool  # a constraint names a flat quantity (FLAT_VALUES)
    extra: list[str]  # gap and dv when a margin needs them
    kin_cons: list[Any]
    crit_cons: list[Any]
    scale: dict[int, float] = field(default_factory=dict)  # by id() of the constraint
    proxy_scale: float = 1.0

    @classmethod
    def of(cls, model: CutInGMM, region: Region) -> _RegionMargins:
        cons = region.constraints
        names = sorted({c.name for c in cons})
        crit = [name for name in names if name in CRITICALITY_QUANTITIES]
        flat = any(c.name in FLAT_VALUES for c in cons)
        extra = ["gap", "dv"] if flat or "ttc" in names else []
        # the support classes' continuous margin (support_margin) needs both of these
        support_extra = ["support_distance", "support_excess"] if "support" in names else []
        other = sorted({*(n for n in names if n not in CRITICALITY_QUANTITIES and n != "ttc"),
                        *extra, *support_extra})
        return cls(model, region, other, crit, flat, extra,
                   kin_cons=[c for c in cons if c.name not in CRITICALITY_QUANTITIES],
                   crit_cons=[c for c in cons if c.name in CRITICALITY_QUANTITIES])

    @property
    def with_ttr(self) -> bool:
        return "ttr_true" in self.crit  # the TTR scan is the costliest part: only when asked

    @property
    def layered(self) -> bool:
        """Kinematic and criticality constraints together (``region_limit_state``'s
        docstring): no row outside the kinematic ones is simulated."""
        return bool(self.kin_cons) and bool(self.crit_cons)

    def quantities(self, z: FloatArray, params: FloatArray | None = None
                   ) -> tuple[FloatArray, dict[str, FloatArray]]:
        if params is None:
            params = self.model.params_matrix(self.model.from_z(z))
        q = self.region.quantities(params, self.other) if self.other else {}
        if self.crit:
            q.update(criticality_quantities(params, self.region.lane_width,
                                            with_ttr=self.with_ttr))
        return params, q

    def raw(self, q: dict[str, FloatArray], c: Any) -> FloatArray:
        """The constraint's unscaled margin (the continuous one for ttc)."""
        if c.name == "ttc":
            return ttc_margin(q["gap"], q["dv"], c.op, float(c.value))
        if c.name == "support":  # the class codes are flat: a continuous margin instead
            return support_margin(self.model, q["support_distance"], q["support_excess"],
                                  c.op, float(c.value))
        sgn = 1.0 if c.op in ("<", "<=") else -1.0
        return sgn * (q[c.name] - float(c.value))

    def spread(self, group: list[Any], q0: dict[str, FloatArray]) -> list[float]:
        """Robust spreads of a group's margins (1 when the group names one quantity:
        then the scale changes none of the sets g <= b)."""
        if len({c.name for c in group}) < 2:
            return [1.0 for _ in group]
        return [_margin_scale(self.raw(q0, c)) for c in group]

    def fit_scales(self, rng: np.random.Generator, n_scale: int) -> None:
        """Each constraint's scale and the flat proxy's, from model draws."""
        model, region, cons = self.model, self.region, self.region.constraints
        if self.layered:
            # kinematic margins are compared among themselves, criticality margins among
            # themselves: only several criticality quantities need simulated scale draws
            x0 = model.params_matrix(model.sample(n_scale, rng))
            q0 = region.quantities(x0, self.other)
            kin_scale = self.spread(self.kin_cons, q0)
            crit_scale = [1.0 for _ in self.crit_cons]
            if len(set(self.crit)) > 1:
                _, q1 = self.quantities(model.sample_z(n_scale // 2, rng))
                crit_scale = self.spread(self.crit_cons, q1)
            for c, sc in zip([*self.kin_cons, *self.crit_cons], [*kin_scale, *crit_scale],
                             strict=True):
                self.scale[id(c)] = sc
            self.proxy_scale = (_margin_scale(q0["gap"] - FLAT_PROXY_HORIZON * q0["dv"])
                                if self.flat else 1.0)
        elif len({c.name for c in cons}) > 1 or not self.crit:
            # criticality regions: half the draws (each is a closed-loop simulation)
            _, q0 = self.quantities(model.sample_z(n_scale // (2 if self.crit else 1), rng))
            for c in cons:
                self.scale[id(c)] = _margin_scale(self.raw(q0, c))
            self.proxy_scale = (_margin_scale(q0["gap"] - FLAT_PROXY_HORIZON * q0["dv"])
                                if self.extra else 1.0)
        else:  # one criticality quantity: its scale does not change the sets g <= b
            for c in cons:
                self.scale[id(c)] = 1.0
            self.proxy_scale = 1.0
            if self.extra:  # the proxy's spread needs no simulation
                x0 = model.params_matrix(model.sample(n_scale, rng))
                q0 = region.quantities(x0, ["gap", "dv"])
                self.proxy_scale = _margin_scale(q0["gap"] - FLAT_PROXY_HORIZON * q0["dv"])

    def margin(self, q: dict[str, FloatArray], c: Any) -> FloatArray:
        s = self.scale[id(c)]
        m = self.raw(q, c) / s
        if c.name in FLAT_VALUES:
            fv = FLAT_VALUES[c.name]
            at_flat = q[c.name] == fv
            sgn = 1.0 if c.op in ("<", "<=") else -1.0
            base = sgn * ((_TTR_FLAT_STANDIN if math.isinf(fv) else fv) - float(c.value)) / s
            outside = at_flat & ~OPERATORS[c.op](np.full(1, fv), float(c.value))[0]
            if outside.any():
                h = (q["gap"] - FLAT_PROXY_HORIZON * q["dv"]) / self.proxy_scale
                m = np.where(outside, max(base, 0.0) + np.logaddexp(0.0, h), m)
        # a strict constraint excludes its threshold (discrete quantities such as ttr_true,
        # a multiple of the step, put mass on it): margin 0 counts as outside
        # (support_margin places its own boundary)
        return np.where(m == 0.0, _TINY, m) if c.op in "<>" and c.name != "support" else m

    def largest(self, q: dict[str, FloatArray], group: list[Any]) -> FloatArray:
        with np.errstate(invalid="ignore", over="ignore"):
            m = np.max(np.stack([self.margin(q, c) for c in group]), axis=0)
        return np.asarray(np.where(np.isnan(m), np.inf, m), dtype=np.float64)

    def __call__(self, z: FloatArray) -> FloatArray:
        model, region = self.model, self.region
        out = np.full(z.shape[0], np.inf)
        # rows farther than R_MAX Mahalanobis units from every component hold no mass worth
        # simulating (an importance density's tails reach them: lane changes lasting hours)
        ok = np.flatnonzero(_near(model, z))
        params = model.params_matrix(model.from_z(z[ok])) if ok.size else None
        if ok.size and region.physical_bounds:  # simulate physical cut-ins only
            assert params is not None
            keep = region.in_bounds(params)
            ok, params = ok[keep], params[keep]
        if ok.size == 0 or params is None:
            return out
        if not self.layered:
            _, q = self.quantities(z[ok], params)  # the rows' parameters are known already
            out[ok] = self.largest(q, list(region.constraints))
            return out
        q = region.quantities(params, self.other)
        m_kin = self.largest(q, self.kin_cons)
        inside = m_kin <= 0
        out[ok[~inside]] = LAYER + m_kin[~inside]
        if inside.any():
            qc = {name: v[inside] for name, v in q.items()}
            qc.update(criticality_quantities(params[inside], region.lane_width,
                                             with_ttr=self.with_ttr))
            out[ok[inside]] = np.minimum(self.largest(qc, self.crit_cons), LAYER)
        return out


#: a layered limit state's offset for rows outside the kinematic constraints (above every
#: criticality margin, which is clipped to it)
LAYER = 1e6


class SubsetSampler(Sampler):
    """Subset simulation as a sampler: P(A) and the final level's samples.

    The sample set is ``n`` of the final level's samples inside A spread evenly over the
    chains (they are Markov-chain samples: correlated, ``ess`` estimated from the last
    level's correlation factor). Each level holds ``max(n_per_level, ceil(n / p0))``
    points, so the final level has at least ``n`` samples inside A.

    Parameters
    ----------
    n_per_level : int
    p0 : float
        Conditional probability of each level.
    proposal_range : float
        Half-width of the component-wise uniform proposal in standard normal space.
    max_seconds : float
        Time budget; exceeded -> ``SamplerError``.
    min_probability : float
        Give up (``EmptyRegionError``) when the levels get below this mass.
    """

    name = "subset"

    def __init__(self, n_per_level: int = 2000, p0: float = 0.1, proposal_range: float = 2.0,
                 max_seconds: float = 120.0, min_probability: float = 1e-14) -> None:
        self.n_per_level = int(n_per_level)
        self.p0 = float(p0)
        self.proposal_range = float(proposal_range)
        self.max_seconds = float(max_seconds)
        self.min_probability = float(min_probability)

    def run(self, problem: Problem, n: int, rng: np.random.Generator) -> SubsetResult:
        """The subset simulation behind ``draw`` (also used for P(A) alone)."""
        limit_state = region_limit_state(problem.model, problem.region, rng)
        per_level = max(self.n_per_level, math.ceil(n / self.p0))
        seed = int(rng.integers(0, 2**31 - 1))

        def counted(z: FloatArray) -> FloatArray:
            problem.n_evals += z.shape[0]
            return limit_state(z)

        return subset_simulation(problem.model, counted, seed, n_per_level=per_level,
                                 p0=self.p0, proposal_range=self.proposal_range,
                                 max_seconds=self.max_seconds,
                                 min_probability=self.min_probability)

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        res = self.run(problem, n, rng)
        z = res.z[problem.region.contains(problem.params(res.z))] if res.z.size else res.z
        if z.shape[0] < n:
            raise EmptyRegionError(
                f"subset simulation ended with {z.shape[0]} samples inside "
                f"{problem.region.describe()}, fewer than n={n}",
                n_draws=res.n_evaluations, n_hits=int(z.shape[0]), p_upper=res.probability)
        pick = z[np.linspace(0, z.shape[0] - 1, n).round().astype(int)]
        if progress is not None:
            progress("subset", n, n)
        last_gamma = res.gamma[-1] if res.gamma else 0.0
        diag = {"subset": res.summary(), "n_evaluations": problem.n_evals,
                "ess": float(min(n, z.shape[0] / (1.0 + last_gamma)))}
        return Draw(z=np.ascontiguousarray(pick), method=self.name, diagnostics=diag,
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits, subset=res)

    def estimate_p(self, run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
        return estimate_from_levels(run, pilot, drawn)

    def estimate_alone(self, run: Run, pilot: Pilot) -> PRegion:
        """P(A) without samples: a subset simulation (after the broadened search when the
        pilot found nothing, which ends an empty region with its bound)."""
        if pilot.n_hits == 0:  # part of the pilot (app.budget.precheck stops at the next stage)
            run.estimator.search(run.problem, run.rng, pilot, 1)
        run.starting("subset simulation")
        return run.estimator.from_subset(run.problem, self.run(run.problem, 1, run.rng),
                                         run.bounds)

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        sub = diagnostics["subset"]
        return [f"subset simulation: {sub['levels']} levels of {sub['n_per_level']}, "
                f"{sub['n_evaluations']} evaluations, CoV {sub['cov']:.2f} "
                f"(independent levels) ... {sub['cov_upper']:.2f} (bound)"]


def estimate_from_levels(run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
    """P(A) of a draw that carries a subset simulation's (or subset-is's) result
    (``PRegionEstimator.from_subset``). For a criticality region the pilot's exact draws
    may overrule it (``PRegionEstimator.contradicts``); the diagnostics then say so."""
    p_region = run.estimator.from_subset(run.problem, drawn.subset, run.bounds,
                                         pilot if run.problem.costly else None)
    if p_region.method != drawn.method:  # overruled by the pilot's exact draws
        drawn.diagnostics["overruled"] = (
            f"{drawn.method}'s P(A) lay below the pilot's exact lower bound (99.9 %): "
            f"P(A) is the pilot's plain estimate ({pilot.n_hits} hits); the samples "
            "may cover only part of the region")
    return p_region
