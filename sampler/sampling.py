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
from sampler.errors import SamplerError
from sampler.methods.probability import PRegion, PRegionEstimator
from sampler.methods.problem import Draw, Pilot, Problem, ProgressFn, Run, Sampler
from sampler.methods.samplers import SAMPLERS, AutoSampler, make_sampler
from sampler.model.gmm import CutInGMM
from sampler.model.support import SupportMeasures
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
        parts = [f"{len(self)} samples of {self.region.describe()} by {self.method}",
                 str(self.p_region)]
        parts.extend(SAMPLERS.get(self.method, Sampler).summarise(self.diagnostics))
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


def _model_info(model: CutInGMM) -> dict[str, Any]:
    return {"features": list(model.features_), "n_components": model.n_components_,
            "training_sha256": getattr(model, "training_", {}).get("sha256"),
            "lane_width": model.lane_width_}


def _settings(strategy: Sampler, est: PRegionEstimator, use_envelope: bool,
              known_region: PRegion | None) -> dict[str, Any]:
    out: dict[str, Any] = {"sampler": strategy.settings(), "estimator": est.settings(),
                           "use_envelope": use_envelope}
    if known_region is not None:
        out["known_region"] = known_region.to_dict()
    return out


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
    known_region: PRegion | None = None,
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
    known_region : PRegion, optional
        P(A) (and P(B)) of this region when it is known already (a catalogue estimates it
        once and its chunks reuse it): it is the result's P(A), and neither P(B) nor P(A)
        is estimated (the generator does not draw for them).
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
    n = _check_n(n)
    seed_i = _seed(seed)
    region = _region(model, constraints, lane_width, physical_bounds)
    strategy = make_sampler(method)
    est = estimator or PRegionEstimator()
    rng = np.random.default_rng(seed_i)
    problem = Problem(model, region, use_envelope=use_envelope)
    bounds = (est.p_bounds(problem, rng) if known_region is None else
              (known_region.p_bounds, known_region.p_bounds_ci[0],
               known_region.p_bounds_ci[1]))
    run = Run(problem, rng, est, bounds, seed_i, progress)
    pilot, drawn, p_region = _draw(strategy, run, n, known_region)
    x, params, derived, measures = _tables(model, region, drawn.z)
    diag = dict(drawn.diagnostics)
    diag["pilot"] = _pilot_diagnostics(pilot)
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
        sampler_settings=_settings(strategy, est, use_envelope, known_region),
        region=region,
        model_info=_model_info(model),
        support=None if measures is None else [measures.record(i) for i in range(n)],
    )


def _check_n(n: Any) -> int:
    """``sample``'s n, checked (an integer in 1 ... 1,000,000)."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 1_000_000:
        raise SamplerError(f"n: expected an integer in 1 ... 1000000, got {n!r}")
    return int(n)


def _draw(strategy: Sampler, run: Run, n: int,
          known_region: PRegion | None) -> tuple[Pilot, Draw, PRegion]:
    """The strategy's pilot, its draw of ``n`` samples and P(A) (the known region's when
    given: then nothing is estimated)."""
    problem, rng, est, progress = run.problem, run.rng, run.estimator, run.progress
    plan = strategy.pilot_plan(problem)
    pilot = est.pilot(problem, rng, need=plan.need, progress=progress, extend=plan.extend)
    strategy.prepare(run, n, pilot)
    drawn = strategy.draw(problem, n, rng, pilot, progress)
    p_region = (strategy.estimate_p(run, pilot, drawn) if known_region is None
                else known_region)
    return pilot, drawn, p_region


def _tables(model: CutInGMM, region: Region, z: FloatArray
            ) -> tuple[FloatArray, pd.DataFrame, pd.DataFrame, SupportMeasures | None]:
    """The drawn points ``z`` in the model's features (x), as parameter vectors (with any
    feature that is not a parameter as a column of its own), their derived quantities and
    their data support (None without the model's support)."""
    x = model.from_z(z)
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
    return x, params, derived, measures


def _pilot_diagnostics(pilot: Pilot) -> dict[str, Any]:
    """The pilot's counts, for the sample set's diagnostics."""
    return {"n_draws": pilot.n_draws, "n_hits": pilot.n_hits,
            "search_draws": pilot.search_draws,
            "n_simulated": pilot.n_simulated,
            "probe_draws": pilot.probe_draws, "plain": pilot.plain,
            "search_hits": int(pilot.search_hits.shape[0])
            if pilot.search_hits.ndim == 2 else 0}


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
    return AutoSampler().estimate_region(model, region, _seed(seed), est, progress)
