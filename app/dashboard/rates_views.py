"""The views of "how often, and how sure" (issue 12): a region's P(A) with its two
intervals and its rates under one model, and two models side by side (marginals with and
without the constraint, P(A) and rates of the same region under each).

Both are bounded like the other views (histograms binned on the server, a fixed number of
samples) and cached by what they depend on (model ids, constraints, n, seed).
"""

from __future__ import annotations

from typing import Any

from app import domain, jsonconv
from app.context import ServiceContext
from app.dashboard.aggregate import histogram
from app.dashboard.views import (
    PARAM_BINS,
    PARAM_LABELS,
    PREVIEW_N_LIMIT,
    _column,
    _model_and_row,
    _reference_draws,
    _views,
    bins_for_both,
    split_constraints,
)
from app.errors import InvalidInput, ServiceError

__all__ = ["compare_models", "region_rates"]


def _uncertain(p_region: dict[str, Any]) -> dict[str, Any]:
    """The P(A) dict of ``domain.sample`` / ``region_uncertainty`` as ``UncertainP``."""
    p = jsonconv.decode(p_region)
    return {"estimate": p.get("estimate"), "mc_ci": p.get("mc_ci") or p.get("ci"),
            "model_ci": p.get("model_ci"), "method": p.get("method"),
            "model_interval": p.get("model_interval"),
            "model_interval_error": p.get("model_interval_error")}


def region_rates(ctx: ServiceContext, model_id: str, constraint_text: str,
                 seed: int) -> dict[str, Any]:
    """P(A) of the region under the model with the "Monte Carlo" and the "model" interval,
    the bootstrap replicates' P(A), and the rates per hour / per 10^6 km (when the model has
    an exposure)."""
    texts = split_constraints(constraint_text)
    mid, model, _ = _model_and_row(ctx, model_id)
    constraints = domain.parse_constraints(texts, field="query.constraints")

    def compute() -> dict[str, Any]:
        p = domain.estimate_region(model, constraints, seed)
        full = domain.region_uncertainty(model, constraints, p)
        return {"model": mid, "constraints": texts, "seed": seed,
                "p_region": _uncertain(full), "rates": full.get("rates"),
                "exposure": getattr(model, "exposure_", None)}

    result: dict[str, Any] = _views(ctx).get(("rates", mid, tuple(texts), seed), compute)
    return result


def compare_models(ctx: ServiceContext, a: str, b: str, constraint_text: str, n: int,
                   seed: int) -> dict[str, Any]:
    """Two models side by side for one region: per parameter the histograms of each
    model's draws inside the physical bounds (unconstrained) and of its samples in the
    region (constrained), on shared bins; P(A) with both intervals and the rates under
    each."""
    if not 1 <= n <= PREVIEW_N_LIMIT:
        raise InvalidInput(f"n must be between 1 and {PREVIEW_N_LIMIT}, got {n}",
                           field="query.n")
    texts = split_constraints(constraint_text)
    constraints = domain.parse_constraints(texts, field="query.constraints")
    sides = []
    for key, model_id in (("a", a), ("b", b)):
        try:
            sides.append(_model_and_row(ctx, model_id))
        except ServiceError as exc:  # 404 or 422 naming the query parameter, not a path
            raise type(exc)(exc.message, field=f"query.{key}") from None

    def compute() -> dict[str, Any]:
        models, frames = [], []
        for mid, model, row in sides:
            reference = _reference_draws(ctx, mid, model)
            drawn = domain.sample(model, constraints, n, seed)
            frames.append((reference, drawn.params))
            models.append({"id": mid, "dataset": row.dataset_id,
                           "n_components": int(model.n_components_),
                           "features": domain.model_features(model),
                           "exposure": getattr(model, "exposure_", None),
                           "p_region": _uncertain(drawn.p_region),
                           "rates": jsonconv.decode(drawn.p_region).get("rates")})
        parameters = []
        for name in domain.PARAM_NAMES:
            cols = [[_column(ref, name), _column(con, name)] for ref, con in frames]
            edges = bins_for_both([c for pair in cols for c in pair], bins=PARAM_BINS)
            parameters.append({
                "name": name, "label": PARAM_LABELS.get(name, name),
                "models": [{"unconstrained": histogram(ref, edges),
                            "constrained": histogram(con, edges)} for ref, con in cols]})
        return {"constraints": texts, "n": n, "seed": seed, "models": models,
                "parameters": parameters}

    cache_key = ("compare", sides[0][0], sides[1][0], tuple(texts), n, seed)
    result: dict[str, Any] = _views(ctx).get(cache_key, compute)
    return result
