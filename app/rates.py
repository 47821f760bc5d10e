"""How often and how sure (issue 12): the response models of P(A) with its two intervals
and of the rates per hour / per 10^6 km, and a catalogue's rates with the check that its
exposure weights sum to the rate.

The figures come from ``sampler.rates.exposure.uncertainty_report`` (stored with a catalogue's
P(A), or computed for a request); this module only types and reshapes them.
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import Field

from app import jsonconv
from app.schemas import ApiModel

__all__ = ["ExposureInfo", "ModelComparison", "ModelInterval", "RateEntry", "RegionRates",
           "RegionReport", "UncertainP", "catalogue_rates"]

class ExposureInfo(ApiModel):
    n_events: int = Field(description="cut-ins counted in the exposure (the training rows)")
    hours: float | None = Field(description="hours driven (vehicle-hours for highD)")
    km: float | None = Field(description="km driven (vehicle-km for highD)")
    source: str = Field(description="where the figures come from")


class RateEntry(ApiModel):
    estimate: float = Field(description="cut-ins of the region per unit of exposure")
    mc_ci: list[float] = Field(description="'Monte Carlo' interval: P(A)'s, times the rate "
                               "of all cut-ins")
    model_ci: list[float] | None = Field(
        description="'model' interval: bootstrap replicates of P(A) times Poisson replicates "
        "of the count (null: the model has no replicates)")
    model_lower_resolved: bool | None = Field(
        default=None, description="false: the model interval's lower end is not resolved "
        "(too few effective samples for the lowest replicates; likely too low)")
    weight_per_sample: float | None = Field(
        default=None, description="each sample's exposure weight in this unit (n of them sum "
        "to the estimate)")


class CutInRate(ApiModel):
    estimate: float
    ci: list[float] = Field(description="exact (Garwood) Poisson interval of the count")


class RegionRates(ApiModel):
    exposure: ExposureInfo
    cutin_rate: dict[str, CutInRate] = Field(description="all cut-ins of the data, per unit")
    confidence: float
    per_hour: RateEntry | None = None
    per_1e6_km: RateEntry | None = None
    from_weights: dict[str, float] | None = Field(
        default=None, description="a catalogue's stored exposure weights summed "
        "(sum_weights = P(A) once every chunk is stored) and times the rate of all cut-ins, "
        "per unit: equal to the estimates when the catalogue is done")


class ModelInterval(ApiModel):
    ci: list[float]
    confidence: float
    median: float | None
    n_boot: int = Field(description="bootstrap refits")
    cov: float | None
    method: str
    n_samples: int = Field(description="samples of the replicates' average inside the region")
    ess: dict[str, float] = Field(description="effective sample size per replicate: min, "
                                  "median, below_min (how many under min_ess), min_ess")
    lower_resolved: bool
    upper_resolved: bool
    note: str | None = None
    replicates_quantiles: dict[str, float] = Field(
        default_factory=dict, description="percentiles p0, p2.5, p10, p50, p90, p97.5, p100 of "
        "the replicates' P(A)")
    replicates: list[float | None] = Field(default_factory=list,
                                           description="each replicate's P(A)")


class UncertainP(ApiModel):
    """P(A) with both intervals: 'Monte Carlo' (the estimator's) and 'model' (the fit's)."""

    estimate: float | None
    mc_ci: list[float | None]
    model_ci: list[float] | None
    method: str | None = None
    model_interval: ModelInterval | None = None
    model_interval_error: str | None = Field(
        default=None, description="why there is no model interval although the model has "
        "bootstrap replicates (their estimate failed, e.g. on a thin region)")


class RegionReport(ApiModel):
    """A region under one model: P(A) with both intervals and the rates."""

    model: str
    constraints: list[str]
    seed: int
    p_region: UncertainP
    rates: RegionRates | None = Field(description="null: the model has no exposure")
    exposure: ExposureInfo | None


class Histogram(ApiModel):
    edges: list[float]
    counts: list[int]
    density: list[float]
    n: int
    n_finite: int
    below: int
    above: int
    n_nonfinite: int


class SideHistograms(ApiModel):
    unconstrained: Histogram = Field(description="draws inside the physical bounds")
    constrained: Histogram = Field(description="samples inside the region")


class ParameterComparison(ApiModel):
    name: str
    label: str
    models: list[SideHistograms] = Field(description="model a, then model b (shared edges)")


class ModelSide(ApiModel):
    id: str
    dataset: str
    n_components: int
    features: list[str]
    exposure: ExposureInfo | None
    p_region: UncertainP
    rates: RegionRates | None


class ModelComparison(ApiModel):
    """Two fitted models side by side for one region."""

    constraints: list[str]
    n: int = Field(description="samples of each model inside the region")
    seed: int
    models: list[ModelSide] = Field(description="a, then b")
    parameters: list[ParameterComparison]


def catalogue_rates(p_region: dict[str, Any] | None,
                    weights: dict[str, Any] | None) -> dict[str, Any] | None:
    """The rates stored with a catalogue's P(A), and its stored exposure weights summed
    (``weights``: the SQL statistics of the exposure weight, count and mean) times the rate
    of all cut-ins: a finished catalogue's weights sum to the rate."""
    if not p_region or not p_region.get("rates"):
        return None
    rates: dict[str, Any] = jsonconv.decode(p_region["rates"])
    if weights and weights.get("count"):
        total = float(weights["count"]) * float(weights["mean"])
        exp = rates["exposure"]
        scale = {"per_hour": exp.get("hours"),
                 "per_1e6_km": None if exp.get("km") is None else exp["km"] / 1e6}
        out = {"sum_weights": total}
        for unit, amount in scale.items():
            if amount and math.isfinite(amount) and unit in rates:
                out[unit] = total * exp["n_events"] / amount
        rates["from_weights"] = out
    return rates
