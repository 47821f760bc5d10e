"""POST /scenarios: a few risk-constrained cut-ins, synchronously."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import Field

from app.deps import ContextDep
from app.schemas import ApiModel, PRegion, SamplingRequest
from app.services import sampling
from sampler.scenario import ScenarioRecord

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


@router.post("", response_model=ScenariosResponse,
             summary="Sample n cut-ins in the risk region, build and score them")
def create_scenarios(body: ScenarioRequest, ctx: ContextDep) -> ScenariosResponse:
    done = sampling.sample_scenarios(ctx, model=body.model, constraints=body.constraints,
                                     n=body.n, seed=body.seed, method=body.sampler,
                                     score=body.score, wagner_scan=body.wagner_scan,
                                     include_scenario=body.include_trajectories)
    return ScenariosResponse(
        model=done.model_id, n=len(done.records), seed=body.seed, sampler=body.sampler,
        constraints=body.constraints, p_region=PRegion.model_validate(done.drawn.p_region),
        diagnostics=done.drawn.diagnostics, scenarios=done.records)
