"""The views of "how often, and how sure" (issue 12): two models side by side, their
marginals with and without a constraint on shared bins (the figures: P(A), rates and the
draws, come from ``app.services.rates``; a region's rates under one model is
``app.services.rates.region_rates`` itself).

The histograms are binned on the server from a fixed number of samples, so the JSON is
bounded; the draws behind them are kept by the service.
"""

from __future__ import annotations

from app import domain
from app.context import ServiceContext
from app.dashboard.aggregate import histogram
from app.dashboard.views import PARAM_BINS, PARAM_LABELS, _column, bins_for_both
from app.rates import Histogram, ModelComparison, ModelSide, ParameterComparison, SideHistograms
from app.services import rates

__all__ = ["compare_models"]


def compare_models(ctx: ServiceContext, a: str, b: str, constraint_text: str, n: int,
                   seed: int) -> ModelComparison:
    """Two models side by side for one region: per parameter the histograms of each
    model's draws inside the physical bounds (unconstrained) and of its samples in the
    region (constrained), on shared bins; P(A) with both intervals and the rates under
    each."""
    comparison = rates.compare_models(ctx, a, b, constraint_text, n, seed)
    models = [ModelSide(id=m.id, dataset=m.dataset, n_components=m.n_components,
                        features=m.features, exposure=m.exposure, p_region=m.p_region,
                        rates=m.rates) for m in comparison.models]
    parameters = []
    for name in domain.PARAM_NAMES:
        cols = [[_column(m.reference, name), _column(m.constrained, name)]
                for m in comparison.models]
        edges = bins_for_both([c for pair in cols for c in pair], bins=PARAM_BINS)
        parameters.append(ParameterComparison(
            name=name, label=PARAM_LABELS.get(name, name),
            models=[SideHistograms(unconstrained=Histogram(**histogram(ref, edges)),
                                   constrained=Histogram(**histogram(con, edges)))
                    for ref, con in cols]))
    return ModelComparison(constraints=comparison.constraints, n=comparison.n,
                           seed=comparison.seed, models=models, parameters=parameters)
