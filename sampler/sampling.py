"""``sample``: the sampler's entry point, and ``SampleSet``, what it returns.

``sample(model, constraints, n, seed, method)`` runs, with one numpy Generator seeded by
``seed`` and advanced in a fixed order:

1. P(B), the model's mass inside the physical bounds (``n_bounds`` plain draws);
2. the pilot: plain Monte-Carlo draws until enough fall inside the region (its exact draws
   are reused as rejection samples and MCMC starting points), and, for rare regions, the
   broadened search (``sampler.methods.probability``);
3. the sampler (``rejection``, ``mcmc``, ``subset`` or ``auto``, see ``sampler.methods.samplers``
   and ``sampler.methods.subset``);
4. P(A) with its interval (plain MC over every model draw made, or importance sampling
   with a defensive mixture when fewer than ``mc_min_hits`` draws hit the region, or the
   subset simulation's estimate when it made the samples).

The same model, constraints, n, seed and settings give the same SampleSet bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from datasets import PARAM_NAMES
from riskcore import ConcreteScenario
from sampler._threads import single_threaded
from sampler.errors import EmptyRegionError, SamplerError
from sampler.methods.envelope import find_envelope
from sampler.methods.mcmc import MCMCSampler
from sampler.methods.probability import PRegion, PRegionEstimator
from sampler.methods.problem import Problem, ProgressFn, Sampler
from sampler.methods.rare import SubsetISSampler
from sampler.methods.samplers import AutoSampler, make_sampler
from sampler.methods.subset import SubsetSampler
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import DERIVED, Region
from sampler.scenario.builder import build_scenario

__all__ = ["SampleSet", "estimate_p_region", "sample"]

#: the derived quantities a model without training rows cannot give
SUPPORT_QUANTITIES = ("support", "support_distance", "support_excess")

FloatArray = NDArray[np.float64]
SCHEMA = "scengen.sample-set/1"


def _num(v: float) -> float | None:
    """JSON has no inf/NaN: they become null (documented in SampleSet.to_dict)."""
    return float(v) if math.isfinite(v) else None


@dataclass(frozen=True, eq=False)
class SampleSet:
    """Samples of the model restricted to a region, with P(A) and diagnostics.

    Attributes
    ----------
    params : DataFrame of shape (n, 8)
        Columns ``PARAM_NAMES`` (SI units), one row per sample (plus any non-parameter
        model features).
    derived : DataFrame of shape (n, len(DERIVED))
        Derived quantities (``ttc``, ``thw``, ``v_ego``, ``lat_offset``, ...).
    log_density : ndarray of shape (n,)
        Model log-density of each sample in original units (not truncated).
    exposure_weights : ndarray of shape (n,)
        ``P(A) / n`` each (see ``sampler.methods.probability``): sums to P(A).
    p_region : PRegion
    method : str
        The sampler that ran (``rejection``, ``mcmc`` or ``subset``); ``requested`` is what
        was asked.
    diagnostics : dict
        The sampler's (acceptance, tau, ESS, ...), JSON-able.
    seed : int
    sampler_settings : dict
    region : Region
    model_info : dict
        Features, number of components, training-data hash of the model.
    """

    params: pd.DataFrame
    derived: pd.DataFrame
    log_density: FloatArray
    exposure_weights: FloatArray
    p_region: PRegion
    method: str
    requested: str
    diagnostics: dict[str, Any]
    seed: int
    sampler_settings: dict[str, Any]
    region: Region
    model_info: dict[str, Any] = field(default_factory=dict)
    #: each sample's data support (``sampler.model.support``: ``support`` class,
    #: ``support_distance``, ``support_excess``, ``support_nearest``, ``density_pct``,
    #: ``support_outside``); None when the model carries no training rows
    support: list[dict[str, Any]] | None = None

    def __len__(self) -> int:
        return len(self.params)

    @property
    def lane_width(self) -> float:
        """The region's lane width in m (the builder needs it to cross where the region
        did)."""
        return float(self.region.lane_width)

    @property
    def constraints(self) -> list[dict[str, Any]]:
        return [c.model_dump() for c in self.region.constraints]

    def params_dict(self, i: int) -> dict[str, float]:
        """Parameter vector of sample ``i``."""
        row = self.params.iloc[i]
        return {k: float(row[k]) for k in PARAM_NAMES}

    def scenario(self, i: int, **builder_kwargs: Any) -> ConcreteScenario:
        """Concrete scenario of sample ``i`` (``build_scenario``; the set's lane width)."""
        kw: dict[str, Any] = {"lane_width": self.region.lane_width}
        kw.update(builder_kwargs)
        prov = {"sample_index": i, "sampler": self.method,
                "constraints": [str(c) for c in self.region.constraints],
                "model_sha256": self.model_info.get("training_sha256")}
        prov.update(kw.pop("provenance", None) or {})
        return build_scenario(self.params_dict(i), seed=self.seed, provenance=prov, **kw)

    def scenarios(self, **builder_kwargs: Any) -> Iterator[ConcreteScenario]:
        for i in range(len(self)):
            yield self.scenario(i, **builder_kwargs)

    def summary(self) -> str:
        """One line: n, method, P(A) with interval, the sampler's main diagnostics."""
        d = self.diagnostics
        parts = [f"{len(self)} samples of {self.region.describe()} by {self.method}",
                 str(self.p_region)]
        if self.method == "mcmc":
            parts.append(f"acceptance {d['acceptance_mean']:.2f} (min {d['acceptance_min']:.2f})"
                         f", tau {d['tau_max']:.1f}, ESS {d['ess']:.0f} "
                         f"(chain {d['ess_chain_min']:.0f}), {d['n_steps']} steps")
            parts.extend(d.get("warnings", []))
        elif self.method == "subset":
            sub = d["subset"]
            parts.append(f"subset simulation: {sub['levels']} levels of {sub['n_per_level']}, "
                         f"{sub['n_evaluations']} evaluations, CoV {sub['cov']:.2f} "
                         f"(independent levels) ... {sub['cov_upper']:.2f} (bound)")
        elif self.method == "subset-is":
            r = d["subset_is"]
            parts.append(f"subset-is: {r['n_evaluations']} evaluations ({r['subset']['levels']} "
                         f"subset levels), CoV {r['cov']:.3f}; independence chains: "
                         f"acceptance {d['acceptance_mean']:.2f}, tau {d['tau_max']:.1f}, "
                         f"ESS {d['ess']:.0f}")
            parts.extend(d.get("warnings", []))
        else:
            parts.append(f"acceptance {d['acceptance_rate']:.3g} of {d['n_draws']} draws")
        return "; ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON (lists, numbers, strings). Infinite or NaN values become null."""
        return {
            "schema": SCHEMA,
            "n": len(self),
            "params": {k: [float(v) for v in self.params[k]] for k in self.params.columns},
            "derived": {k: [_num(float(v)) for v in self.derived[k]]
                        for k in self.derived.columns},
            "log_density": [_num(float(v)) for v in self.log_density],
            "exposure_weights": [float(v) for v in self.exposure_weights],
            "p_region": self.p_region.to_dict(),
            "method": self.method,
            "requested_method": self.requested,
            "diagnostics": self.diagnostics,
            "seed": self.seed,
            "sampler_settings": self.sampler_settings,
            "constraints": self.constraints,
            "region": self.region.model_dump(),
            "model": self.model_info,
            "support": self.support,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SampleSet:
        """Rebuild from ``to_dict`` (nulls in derived values come back as NaN)."""
        if data.get("schema") != SCHEMA:
            raise SamplerError(f"schema: expected {SCHEMA!r}, got {data.get('schema')!r}")

        def arr(values: Iterable[Any]) -> FloatArray:
            return np.array([np.nan if v is None else float(v) for v in values])

        return cls(
            params=pd.DataFrame({k: arr(v) for k, v in data["params"].items()}),
            derived=pd.DataFrame({k: arr(v) for k, v in data["derived"].items()}),
            log_density=arr(data["log_density"]),
            exposure_weights=arr(data["exposure_weights"]),
            p_region=PRegion.from_dict(data["p_region"]),
            method=data["method"],
            requested=data["requested_method"],
            diagnostics=dict(data["diagnostics"]),
            seed=int(data["seed"]),
            sampler_settings=dict(data["sampler_settings"]),
            region=Region.model_validate(data["region"]),
            model_info=dict(data.get("model") or {}),
            support=None if data.get("support") is None else list(data["support"]),
        )


def _region(model: CutInGMM, constraints: Any, lane_width: float | None,
            physical_bounds: bool) -> Region:
    if isinstance(constraints, Region):
        return constraints.bind(model)
    if constraints is None:
        constraints = ()
    width = model.lane_width_ if lane_width is None else lane_width
    return Region.from_constraints(constraints, lane_width=width,
                                   physical_bounds=physical_bounds).bind(model)


def _seed(seed: int | None) -> int:
    if seed is None:
        entropy: Any = np.random.SeedSequence().entropy
        return int(entropy) % (2**63)  # fresh, but recorded
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise SamplerError(f"seed: expected a non-negative integer, got {seed!r}")
    return int(seed)


def _costly(region: Region) -> bool:
    """Whether the region has a criticality constraint (closed-loop simulations)."""
    return any(c.tier == 2 for c in region.constraints)


#: A region whose criticality constraints are all on ``SPLIT_QUANTITIES`` and which has
#: no half-space envelope (no kinematic constraint such as ``ttc<3``) is estimated in two
#: parts split at this TTC when the pilot finds too few hits: inside the
#: ``ttc < SPLIT_TTC`` envelope (plain Monte Carlo there, exact, when its budget allows)
#: and outside it (subset-is). ``btn`` has a second route outside it (the cutter brakes
#: after a cut-in at a safe TTC) that subset-is over the whole region under-represents:
#: its intervals covered 5-8 of 10 seeds, the split's 10 of 10. On ``ttr_true`` the split
#: cost 3x the simulations and its outside part's levels can fail to converge, so it is
#: not used there (docs/sampler.md, "Standalone `btn` regions: split at the envelope").
SPLIT_TTC = 3.0
SPLIT_QUANTITIES = frozenset({"btn", "a_req"})


def _split_parts(region: Region) -> list[Region] | None:
    """The two parts of a region ``auto`` estimates apart (see ``SPLIT_TTC``), or None
    when it is not such a region: a criticality constraint not on ``SPLIT_QUANTITIES``
    (or none), a constraint on ``ttc`` already, or no half-space envelope for
    ``ttc < SPLIT_TTC`` (the model lacks gap/dv)."""
    critical = {c.name for c in region.constraints if c.tier == 2}
    if not critical or not critical <= SPLIT_QUANTITIES:
        return None
    if any(c.name == "ttc" for c in region.constraints):
        return None
    model = region._model
    if model is None:
        return None
    if find_envelope(model, region) is not None:
        return None
    parts = [Region.from_constraints([*region.constraints, extra],
                                     lane_width=region.lane_width,
                                     physical_bounds=region.physical_bounds).bind(model)
             for extra in (f"ttc<{SPLIT_TTC:g}", f"ttc>={SPLIT_TTC:g}")]
    return parts if find_envelope(model, parts[0]) is not None else None


def _split_estimate(model: CutInGMM, parts: list[Region], seed: int, est: PRegionEstimator,
                    bounds: tuple[float, float, float],
                    progress: ProgressFn | None) -> tuple[PRegion, list[dict[str, Any]]]:
    """P(A) as the sum of its parts' estimates (``PRegionEstimator.combine``), each from
    ``estimate_p_region`` with its own seed derived from ``seed``; and the parts' figures
    for the diagnostics. A part found empty counts with its upper bound as its error (its
    ``EmptyRegionError`` is raised when the levels stalled, so that the bound is not
    reliable, or when every part is empty)."""
    out: list[PRegion] = []
    info: list[dict[str, Any]] = []
    empty: list[EmptyRegionError] = []
    for k, part in enumerate(parts):
        child = int(np.random.SeedSequence([seed, 12, k]).generate_state(1, np.uint64)[0])
        child %= 2**63
        try:
            p = estimate_p_region(model, part, child, estimator=est, progress=progress)
        except EmptyRegionError as exc:
            if exc.stalled is not None or not math.isfinite(exc.p_upper):
                raise
            empty.append(exc)
            p = PRegion(estimate=0.0, ci_low=0.0, ci_high=min(1.0, exc.p_upper / bounds[0]),
                        confidence=est.confidence, method="empty", n_draws=exc.n_draws,
                        n_hits=0, p_bounds=bounds[0], p_bounds_ci=(bounds[1], bounds[2]),
                        p_joint=0.0)
        out.append(p)
        info.append({"constraints": part.describe(), "seed": child, **p.to_dict()})
    if len(empty) == len(parts):
        raise empty[-1]
    return est.combine(out, bounds), info


def _model_info(model: CutInGMM) -> dict[str, Any]:
    return {"features": list(model.features_), "n_components": model.n_components_,
            "training_sha256": getattr(model, "training_", {}).get("sha256"),
            "lane_width": model.lane_width_}


@single_threaded
def sample(
    model: CutInGMM,
    constraints: Iterable[Any] | Region | None = (),
    n: int = 100,
    seed: int | None = None,
    method: str | Sampler = "auto",
    *,
    lane_width: float | None = None,
    physical_bounds: bool = True,
    estimator: PRegionEstimator | None = None,
    use_envelope: bool = True,
    progress: ProgressFn | None = None,
) -> SampleSet:
    """Draw ``n`` samples of ``model`` restricted to a region.

    Parameters
    ----------
    model : CutInGMM
        Fitted or loaded.
    constraints : iterable of Constraint / mapping / short-form str, or a Region
        E.g. ``["ttc<3"]``. The physical bounds are added unless ``physical_bounds=False``.
    n : int
        Number of samples (1 ... 1,000,000).
    seed : int, optional
        Seed of everything random; None draws a fresh one (recorded in the result).
    method : {"auto", "rejection", "mcmc", "subset", "subset-is"} or Sampler
    lane_width : float, optional
        Lane width in m; default the model's ``lane_width_``.
    estimator : PRegionEstimator, optional
        Pilot, search and P(A) settings.
    use_envelope : bool
        Draw from the model restricted to the region's half-space envelope when one exists
        (``sampler.methods.envelope``); False draws from the whole model.
    progress : callable (stage, done, total), optional

    Returns
    -------
    SampleSet

    Raises
    ------
    EmptyRegionError
        The region has no (or practically no) mass: after a bounded number of draws, with
        the mass found.
    SamplerError, ConstraintError
        Bad arguments.
    """
    model.check_fitted()
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 1_000_000:
        raise SamplerError(f"n: expected an integer in 1 ... 1000000, got {n!r}")
    n = int(n)
    seed_i = _seed(seed)
    region = _region(model, constraints, lane_width, physical_bounds)
    strategy = make_sampler(method)
    est = estimator or PRegionEstimator()
    rng = np.random.default_rng(seed_i)
    problem = Problem(model, region, use_envelope=use_envelope)

    bounds = est.p_bounds(problem, rng)
    need = getattr(getattr(strategy, "mcmc", strategy), "n_walkers", 0)
    if isinstance(strategy, SubsetSampler | SubsetISSampler):
        need = 0  # subset simulation finds its own way in
    elif isinstance(strategy, AutoSampler):
        # no pilot hit: the broadened search (which ends empty regions); few: subset-is.
        # Not for criticality regions: 10^5-10^6 simulations; subset-is ends empty ones
        need = 0 if _costly(region) else 1
    pilot = est.pilot(problem, rng, need=need, progress=progress,
                      extend=isinstance(strategy, AutoSampler))
    if isinstance(strategy, AutoSampler) and strategy.choose(
            n, pilot, _costly(region)).name == "mcmc":
        est.search(problem, rng, pilot, strategy.mcmc.n_walkers)
    drawn = strategy.draw(problem, n, rng, pilot, progress)
    parts = (_split_parts(region) if isinstance(strategy, AutoSampler)
             and drawn.subset is not None and est.known is None and not pilot.plain
             else None)
    if pilot.plain and pilot.n_hits > 0 and isinstance(strategy, AutoSampler):
        # P(A) from the extended pilot's plain run alone (exact, unbiased; the draws
        # rejection adds were continued until enough hits, which would bias it)
        p_region = est.estimate(problem, rng, mc_draws=pilot.n_draws, mc_hits=pilot.n_hits,
                                region_z=pilot.hits, bounds=bounds, plain=True)
    elif parts is not None:
        # P(A) as estimate_p_region gives it, from the two parts; the samples are still
        # those of the whole region's subset-is run
        p_region, info = _split_estimate(model, parts, seed_i, est, bounds, progress)
        drawn.diagnostics["split"] = {
            "parts": info, "whole_region_estimate": float(drawn.subset.probability),
            "note": f"P(A) is the sum of two parts estimated apart (ttc < {SPLIT_TTC:g} "
                    "and the rest); the samples come from one subset-is run over the whole "
                    "region, which may under-represent the part outside ttc < 3"}
    elif drawn.subset is not None:
        p_region = est.from_subset(problem, drawn.subset, bounds,
                                   pilot if _costly(region) else None)
        if p_region.method != drawn.method:  # overruled by the pilot's exact draws
            drawn.diagnostics["overruled"] = (
                f"{drawn.method}'s P(A) lay below the pilot's exact lower bound (99.9 %): "
                f"P(A) is the pilot's plain estimate ({pilot.n_hits} hits); the samples "
                "may cover only part of the region")
    else:
        p_region = est.estimate(problem, rng, mc_draws=drawn.mc_draws, mc_hits=drawn.mc_hits,
                                region_z=drawn.z, bounds=bounds, plain=pilot.plain)
    x = model.from_z(drawn.z)
    params = pd.DataFrame(model.params_matrix(x), columns=list(PARAM_NAMES))
    for j, f in enumerate(model.features_):
        if f not in PARAM_NAMES:
            params[f] = x[:, j]
    full = params[list(PARAM_NAMES)].to_numpy()
    has_support = model.support_ is not None
    derived = pd.DataFrame(region.quantities(
        full, [k for k in DERIVED if has_support or k not in SUPPORT_QUANTITIES]))
    measures = model.support_measures(full, with_density=True) if has_support else None
    if not region.contains(params[list(PARAM_NAMES)].to_numpy()).all():  # pragma: no cover
        raise SamplerError("internal error: a sample violates its region")
    diag = dict(drawn.diagnostics)
    diag["pilot"] = {"n_draws": pilot.n_draws, "n_hits": pilot.n_hits,
                     "search_draws": pilot.search_draws,
                     "n_simulated": pilot.n_simulated,
                     "probe_draws": pilot.probe_draws, "plain": pilot.plain,
                     "search_hits": int(pilot.search_hits.shape[0])
                     if pilot.search_hits.ndim == 2 else 0}
    return SampleSet(
        params=params,
        derived=derived,
        log_density=model.log_density(x),
        exposure_weights=np.full(n, p_region.estimate / n),
        p_region=p_region,
        method=drawn.method,
        requested=strategy.name,
        diagnostics=diag,
        seed=seed_i,
        sampler_settings={"sampler": strategy.settings(), "estimator": est.settings(),
                          "use_envelope": use_envelope},
        region=region,
        model_info=_model_info(model),
        support=None if measures is None else [measures.record(i) for i in range(n)],
    )


@single_threaded
def estimate_p_region(model: CutInGMM, constraints: Iterable[Any] | Region | None = (),
                      seed: int | None = None, *, lane_width: float | None = None,
                      physical_bounds: bool = True,
                      estimator: PRegionEstimator | None = None,
                      progress: ProgressFn | None = None) -> PRegion:
    """P(A) of a region under the model with its interval, without keeping samples.

    Plain MC when the pilot finds enough hits; when it finds fewer than the MCMC walkers,
    subset-is (``sampler.methods.rare``) for criticality regions and subset simulation otherwise
    (as ``auto``); otherwise a short MCMC run supplies the importance sampler's proposal
    (see ``sampler.methods.probability``). ``progress(stage, done, total)`` hears the pilot's
    counts and the start of each later stage (the estimate does not depend on it).
    """
    model.check_fitted()
    region = _region(model, constraints, lane_width, physical_bounds)
    est = estimator or PRegionEstimator()
    seed_i = _seed(seed)
    rng = np.random.default_rng(seed_i)
    problem = Problem(model, region)
    bounds = est.p_bounds(problem, rng)
    mcmc = MCMCSampler()
    pilot = est.pilot(problem, rng, need=0, progress=progress, extend=True)

    def starting(stage: str) -> None:
        if progress is not None:
            progress(stage, 0, 1)

    if pilot.n_hits >= est.mc_min_hits or (pilot.plain and pilot.n_hits > 0):
        return est.estimate(problem, rng, mc_draws=pilot.n_draws, mc_hits=pilot.n_hits,
                            region_z=pilot.hits, bounds=bounds, plain=pilot.plain)
    if pilot.n_hits < mcmc.n_walkers:  # as ``auto``: too few hits -> subset(-is)
        if not _costly(region):
            starting("subset simulation")
            if pilot.n_hits == 0:
                est.search(problem, rng, pilot, 1)  # ends an empty region with its bound
            return est.from_subset(problem, SubsetSampler().run(problem, 1, rng), bounds)
        parts = _split_parts(region)
        if parts is not None:
            return _split_estimate(model, parts, seed_i, est, bounds, progress)[0]
        starting("subset-is (rare-event estimate)")
        result = SubsetISSampler().run(problem, rng)
        return est.from_subset(problem, result, bounds, pilot)
    drawn = mcmc.draw(problem, 500, rng, pilot, progress)
    return est.estimate(problem, rng, mc_draws=pilot.n_draws, mc_hits=pilot.n_hits,
                        region_z=drawn.z, bounds=bounds)
