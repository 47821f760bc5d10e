"""How often, and how sure (issue 12): a region's P(A) with its two intervals and its rates
under one model, and two models compared on the same region.

Both are bounded (a fixed number of samples) and kept per what they depend on (model ids,
constraints, n, seed) in the context's caches. The comparison's histograms are the
dashboard's business (``app.dashboard.rates_views``); this module gives it each model's
draws, P(A) and rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pandas as pd

from app import domain, jsonconv
from app.context import ServiceContext
from app.errors import InvalidInput, ServiceError
from app.rates import ExposureInfo, ModelInterval, RegionRates, RegionReport, UncertainP
from app.schemas import PRegionJSON
from app.services.models import model_and_row
from app.services.sampling import reference_draws, split_constraints

__all__ = [
    "COMPARE_N_LIMIT",
    "ComparedModel",
    "Comparison",
    "compare_models",
    "region_rates",
    "uncertain_p",
]

#: largest n of a comparison's constrained samples per model
COMPARE_N_LIMIT = 5000


def uncertain_p(p_region: PRegionJSON) -> UncertainP:
    """The P(A) dict of ``domain.sample`` / ``region_uncertainty`` as ``UncertainP``."""
    p = jsonconv.decode(p_region)
    interval = p.get("model_interval")
    return UncertainP(estimate=p.get("estimate"), mc_ci=p.get("mc_ci") or p.get("ci"),
                      model_ci=p.get("model_ci"), method=p.get("method"),
                      model_interval=None if interval is None
                      else ModelInterval.model_validate(interval),
                      model_interval_error=p.get("model_interval_error"))


def _rates(rates: dict[str, Any] | None) -> RegionRates | None:
    """The rates of an uncertainty report (``sampler.rates``) as ``RegionRates``."""
    return None if rates is None else RegionRates.model_validate(rates)


def _exposure(exposure: dict[str, Any] | None) -> ExposureInfo | None:
    """A model's exposure (``CutInGMM.exposure_``) as ``ExposureInfo``."""
    return None if exposure is None else ExposureInfo.model_validate(exposure)


def _cache(ctx: ServiceContext) -> Any:
    return ctx.cache("rates", 64)


def region_rates(ctx: ServiceContext, model_id: str, constraint_text: str,
                 seed: int) -> RegionReport:
    """P(A) of the region under the model with the "Monte Carlo" and the "model" interval,
    the bootstrap replicates, and the rates per hour / per 10^6 km (when the model has an
    exposure): the fields of ``app.rates.RegionReport``."""
    texts = split_constraints(constraint_text)
    mid, model, _ = model_and_row(ctx, model_id)
    constraints = domain.parse_constraints(texts, field="query.constraints")

    def compute() -> RegionReport:
        p = domain.estimate_region(model, constraints, seed)
        full = domain.region_uncertainty(model, constraints, p)
        return RegionReport(model=mid, constraints=texts, seed=seed,
                            p_region=uncertain_p(full),
                            rates=_rates(jsonconv.decode(full.get("rates"))),
                            exposure=_exposure(model.exposure_))

    result: RegionReport = _cache(ctx).get(("rates", mid, tuple(texts), seed), compute)
    return result


@dataclass(frozen=True)
class ComparedModel:
    """One side of a comparison: the model, its P(A) and rates in the region, and its
    draws without (``reference``) and with (``constrained``) the constraints."""

    id: str
    dataset: str
    n_components: int
    features: list[str]
    exposure: ExposureInfo | None
    p_region: UncertainP
    rates: RegionRates | None
    reference: pd.DataFrame
    constrained: pd.DataFrame


@dataclass(frozen=True)
class Comparison:
    constraints: list[str]
    n: int
    seed: int
    models: tuple[ComparedModel, ComparedModel]


def compare_models(ctx: ServiceContext, a: str, b: str, constraint_text: str, n: int,
                   seed: int) -> Comparison:
    """Two models on one region: each model's unconstrained reference draws, ``n`` samples
    in the region, P(A) with both intervals and the rates."""
    if not 1 <= n <= COMPARE_N_LIMIT:
        raise InvalidInput(f"n must be between 1 and {COMPARE_N_LIMIT}, got {n}",
                           field="query.n")
    texts = split_constraints(constraint_text)
    constraints = domain.parse_constraints(texts, field="query.constraints")
    sides = []
    for key, model_id in (("a", a), ("b", b)):
        try:
            sides.append(model_and_row(ctx, model_id))
        except ServiceError as exc:  # 404 or 422 naming the query parameter, not a path
            raise type(exc)(exc.message, field=f"query.{key}") from None

    def side(mid: str, model: Any, row: Any) -> ComparedModel:
        reference = reference_draws(ctx, mid, model)
        drawn = domain.sample(model, constraints, n, seed)
        return ComparedModel(id=mid, dataset=row.dataset_id,
                             n_components=int(model.n_components_),
                             features=domain.model_features(model),
                             exposure=_exposure(model.exposure_),
                             p_region=uncertain_p(drawn.p_region),
                             rates=_rates(jsonconv.decode(drawn.p_region).get("rates")),
                             reference=reference, constrained=drawn.params)

    def compute() -> Comparison:
        first, second = (side(*s) for s in sides)
        return Comparison(constraints=texts, n=n, seed=seed, models=(first, second))

    cache_key = ("compare", sides[0][0], sides[1][0], tuple(texts), n, seed)
    result: Comparison = _cache(ctx).get(cache_key, compute)
    return result
