"""Constrained sampling for the service: constraints, samples, P(A)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from app import budget, jsonconv
from app.errors import InvalidInput, domain_field
from app.schemas import PRegionJSON, PRegionReport
from riskcore import FieldError
from sampler import (
    Constraint,
    CutInGMM,
    EmptyRegionError,
    PRegion,
    SamplerError,
    SampleSet,
    estimate_p_region,
    parse_constraint,
)
from sampler import sample as sampler_sample
from sampler.methods import ProgressFn
from sampler.rates import region_report, uncertainty_report
from sampler.region import Region

__all__ = ["SampleResult", "estimate_region", "parse_constraints", "region_uncertainty",
           "sample"]


#: binary quantities (1/0) with a continuous twin that is > 0 exactly on the same rows:
#: the rare-event estimator's levels need a quantity that grows towards the region
#: (subset simulation on a 0/1 indicator has no intermediate levels: "levels did not
#: converge"); checked on 3,000 draws of ttc<1.5 (32 collisions, min impact 1.47 m/s)
CONTINUOUS_TWINS = {"r157_collision": "r157_impact_speed"}


def continuous_twin(constraint: Constraint) -> Constraint:
    """``r157_collision > c`` (0 <= c < 1) or ``>= c`` (0 < c <= 1), i.e. "the R157
    driver collides", as ``r157_impact_speed > 0``: the same rows, but a limit state the
    rare-event estimator can climb (issue 27 finding 7: ``r157_collision>0.5`` failed
    after 10 s while ``r157_impact_speed>0`` gave P(A) 2.13e-7). Other constraints as
    they are."""
    twin = CONTINUOUS_TWINS.get(constraint.name)
    if twin is None:
        return constraint
    c, op = float(constraint.value), constraint.op
    if (op == ">" and 0 <= c < 1) or (op == ">=" and 0 < c <= 1):
        return Constraint(name=twin, op=">", value=0.0)
    return constraint


def parse_constraints(texts: Sequence[str], field: str = "body.constraints") -> list[Constraint]:
    """Parse constraint texts; a bad one is InvalidInput naming its position. The sampler's
    message already quotes the constraint. A binary quantity meaning "collides" becomes
    its continuous twin (``continuous_twin``)."""
    out = []
    for i, text in enumerate(texts):
        try:
            out.append(continuous_twin(parse_constraint(text)))
        except SamplerError as exc:
            raise InvalidInput(str(exc), field=f"{field}.{i}") from None
    return out


@dataclass(frozen=True)
class SampleResult:
    """What the service keeps of a sampler SampleSet."""

    params: pd.DataFrame  # columns PARAM_NAMES, one row per sample
    weights: NDArray[np.float64]  # exposure weight per sample
    p_region: PRegionJSON
    diagnostics: dict[str, Any]
    lane_width: float  # m, the region's lane width: build the scenarios with it
    sample_set: SampleSet | None = None  # the sampler's set (for ``add_region_report``)


def region_dict(pr: PRegion) -> PRegionJSON:
    """A PRegion as JSON: its fields plus ``ci`` = [ci_low, ci_high]."""
    out = dict(pr.to_dict())
    out["ci"] = [out.get("ci_low"), out.get("ci_high")]
    encoded: PRegionJSON = jsonconv.encode(out)
    return encoded


def _sampling_error(exc: FieldError) -> InvalidInput:
    field = domain_field(exc) or "body"  # the error's structured field, under "body."
    if isinstance(exc, EmptyRegionError):
        return InvalidInput(f"the region is (practically) empty: {exc}", field=field)
    return InvalidInput(f"sampling failed: {exc}", field=field)


def region_of(data: Mapping[str, Any]) -> PRegion:
    """A stored P(A) dict (``region_dict``, maybe JSON-encoded) back as a PRegion."""
    values = jsonconv.decode(data)
    names = {f.name for f in fields(PRegion)}
    return PRegion.from_dict({k: v for k, v in values.items() if k in names})


def sample(model: CutInGMM, constraints: Sequence[Constraint], n: int, seed: int | None,
           method: str = "auto", known_region: Mapping[str, Any] | None = None, *,
           report: bool = True, lane_width: float | None = None, use_envelope: bool = True,
           progress: ProgressFn | None = None) -> SampleResult:
    """``n`` samples of ``model`` in the region (``sampler.sample``; ``seed`` None: a fresh
    one, kept in the result's sample set). ``known_region``: the region's P(A) dict when it
    is already estimated (reused, not estimated again). ``report=False`` leaves the model
    interval and rates out of ``p_region`` for the caller to add later
    (``add_region_report``, e.g. while the samples are being scored). ``lane_width``,
    ``use_envelope`` and ``progress``: as ``sampler.sample``."""
    known = None if known_region is None else region_of(known_region)
    try:
        ss = sampler_sample(model, list(constraints), n, seed, method, known_region=known,
                            lane_width=lane_width, use_envelope=use_envelope,
                            progress=budget.checked(progress))
    except FieldError as exc:  # the user's input; a library's ValueError is our bug (500)
        raise _sampling_error(exc) from None
    diagnostics = jsonconv.encode(dict(ss.diagnostics))
    diagnostics["method"] = ss.method
    diagnostics["requested_method"] = ss.requested
    result = SampleResult(
        params=ss.params,
        weights=np.asarray(ss.exposure_weights, dtype=np.float64),
        p_region=region_dict(ss.p_region),
        diagnostics=diagnostics,
        lane_width=float(ss.region.lane_width),
        sample_set=ss,
    )
    if report and known_region is None:
        add_region_report(model, result)
    return result


def add_region_report(model: CutInGMM, result: SampleResult) -> None:
    """Issue 12: the "model" interval of P(A) beside the Monte Carlo one, and rates per hour
    / 10^6 km with both (``sampler.rates.exposure.region_report``), added to ``result.p_region``
    when the model has bootstrap refits or an exposure."""
    if result.sample_set is None or not (model.bootstrap_ or model.exposure_):
        return
    merged: PRegionJSON = {**result.p_region,
                           **_uncertainty_fields(region_report(model, result.sample_set))}
    result.p_region.update(merged)


def estimate_region(model: CutInGMM, constraints: Sequence[Constraint],
                    seed: int, progress: ProgressFn | None = None) -> PRegionJSON:
    """P(A) of the constraint region under the model: ``{"estimate", "ci": [lo, hi], ...}``;
    ``progress`` hears the estimator's stages."""
    try:
        return region_dict(estimate_p_region(model, list(constraints), seed,
                                             progress=budget.checked(progress)))
    except FieldError as exc:  # the user's input; a library's ValueError is our bug (500)
        raise _sampling_error(exc) from None


def _uncertainty_fields(report: dict[str, Any]) -> PRegionReport:
    """The keys a P(A) dict gets from ``uncertainty_report``: ``mc_ci``, ``model_ci``,
    ``model_interval`` and ``rates`` (JSON-encoded); ``model_interval_error`` when the
    model interval could not be estimated."""
    out: dict[str, Any] = {"mc_ci": report["p_region"]["mc_ci"],
                           "model_ci": report["p_region"]["model_ci"]}
    if "model_interval_error" in report["p_region"]:
        out["model_interval_error"] = report["p_region"]["model_interval_error"]
    for key in ("model_interval", "rates"):
        if key in report:
            out[key] = report[key]
    encoded: PRegionReport = jsonconv.encode(out)
    return encoded


def region_uncertainty(model: CutInGMM, constraints: Sequence[Constraint],
                       p_region: PRegionJSON,
                       n_samples: int | None = None,
                       per_replicate: bool = False) -> PRegionJSON:
    """``p_region`` (a ``region_dict``) with the "model" interval beside the Monte Carlo one
    and the rates per hour / per 10^6 km with both, when the model has bootstrap replicates
    and an exposure (``sampler.rates.exposure.uncertainty_report``); unchanged otherwise.
    ``per_replicate``: see ``sampler.rates.exposure.model_interval``."""
    if not (model.bootstrap_ or model.exposure_):
        return p_region
    region = Region.from_constraints(list(constraints), lane_width=model.lane_width_).bind(model)
    try:
        report = uncertainty_report(model, region_of(p_region), region, n_samples=n_samples,
                                    per_replicate=per_replicate)
    except FieldError as exc:  # the user's input; a library's ValueError is our bug (500)
        raise _sampling_error(exc) from None
    out: PRegionJSON = {**p_region, **_uncertainty_fields(report)}
    return out
