"""POST /scenarios: a few risk-constrained cut-ins, synchronously."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter
from pydantic import Field

from app import domain
from app.context import ServiceContext
from app.deps import ContextDep
from app.errors import InvalidInput
from app.limits import check_constraints
from app.schemas import ApiModel, PRegion, SamplingRequest
from sampler.scenario import ScenarioRecord, score_part

router = APIRouter(prefix="/scenarios", tags=["scenarios"])


class ScenarioRequest(SamplingRequest):
    n: int = Field(default=10, ge=1, description="number of scenarios (≤ the synchronous "
                   "limit, see SCENGEN_SYNC_N_LIMIT)")
    score: bool = Field(default=True, description="score each scenario with the TTR risk")
    include_trajectories: bool = Field(default=False,
                                       description="include the concrete scenarios' JSON")


class ScenariosResponse(ApiModel):
    model: str = Field(description="id of the model sampled")
    n: int
    seed: int
    sampler: str = Field(description="the sampler asked for (diagnostics.method: the one used)")
    constraints: list[str]
    p_region: PRegion
    diagnostics: dict[str, Any] = Field(description="the sampler's diagnostics")
    scenarios: list[ScenarioRecord]


#: below this many vectors the request scores them itself (a pool round trip costs more)
POOL_MIN_N = 8


def _score(ctx: ServiceContext, drawn: domain.SampleResult,
           body: ScenarioRequest) -> Callable[[], list[ScenarioRecord]]:
    """Start scoring the drawn vectors (``score_vector`` each) on the service's executor,
    split in one part per worker slot; the returned function waits for the records. A few
    vectors, or nothing to score, are done here when the function is called."""
    kwargs: dict[str, Any] = {"lane_width": drawn.lane_width, "seed": body.seed,
                              "score": body.score, "include_scenario": body.include_trajectories}
    table, weights = drawn.params, [float(w) for w in drawn.weights]
    n = len(table)
    if not body.score or n < POOL_MIN_N:
        return lambda: score_part(table, 0, weights, kwargs)
    parts = min(n, 4)
    starts = [n * k // parts for k in range(parts + 1)]
    results = ctx.executor.map_later(
        score_part, [table.iloc[a:b].reset_index(drop=True) for a, b in itertools.pairwise(starts)],
        starts[:-1], [weights[a:b] for a, b in itertools.pairwise(starts)], [kwargs] * parts)
    return lambda: [record for part in results() for record in part]


@router.post("", response_model=ScenariosResponse,
             summary="Sample n cut-ins in the risk region, build and score them")
def create_scenarios(body: ScenarioRequest, ctx: ContextDep) -> ScenariosResponse:
    limit = ctx.settings.sync_n_limit
    if body.n > limit:
        raise InvalidInput(f"n = {body.n} is over the synchronous limit of {limit}; use "
                           "POST /catalogues for larger sets", field="body.n")
    model_id = ctx.resolve_model_id(body.model)
    model = ctx.model(model_id, field="body.model")
    check_constraints(body.constraints, ctx.settings)
    constraints = domain.parse_constraints(body.constraints)
    drawn = domain.sample(model, constraints, body.n, body.seed, method=body.sampler,
                          report=False)
    later = _score(ctx, drawn, body)  # the workers score while this thread ...
    domain.add_region_report(model, drawn)  # ... adds the model interval, rates
    records = later()
    return ScenariosResponse(
        model=model_id, n=len(records), seed=body.seed, sampler=body.sampler,
        constraints=body.constraints, p_region=PRegion.model_validate(drawn.p_region),
        diagnostics=drawn.diagnostics, scenarios=records)
