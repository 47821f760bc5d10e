"""POST /scenarios: a few risk-constrained cut-ins, synchronously."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from app import domain
from app.deps import ContextDep
from app.errors import InvalidInput
from app.jobs.chunk import scenario_seed

router = APIRouter(prefix="/scenarios", tags=["scenarios"])

SEED_MAX = 2**63 - 1


class ScenarioRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    model: str = Field(default="default", description="model id ('default': the embedded "
                       "data's model)")
    constraints: list[str] = Field(default_factory=lambda: ["ttc<3"],
                                   description="risk-region constraints, e.g. 'ttc<3'")
    n: int = Field(default=10, ge=1, description="number of scenarios (≤ the synchronous "
                   "limit, see SCENGEN_SYNC_N_LIMIT)")
    seed: int = Field(default=0, ge=0, le=SEED_MAX)
    sampler: Literal["auto", "rejection", "mcmc"] = "auto"
    score: bool = Field(default=True, description="score each scenario with the TTR risk")
    include_trajectories: bool = Field(default=False,
                                       description="include the concrete scenarios' JSON")


@router.post("", summary="Sample n cut-ins in the risk region, build and score them")
def create_scenarios(body: ScenarioRequest, ctx: ContextDep) -> dict[str, Any]:
    limit = ctx.settings.sync_n_limit
    if body.n > limit:
        raise InvalidInput(f"n = {body.n} is over the synchronous limit of {limit}; use "
                           "POST /catalogues for larger sets", field="body.n")
    model_id = ctx.resolve_model_id(body.model)
    model = ctx.model(model_id, field="body.model")
    constraints = domain.parse_constraints(body.constraints)
    drawn = domain.sample(model, constraints, body.n, body.seed, method=body.sampler)
    names = list(domain.PARAM_NAMES)
    table = drawn.params[names].to_numpy(dtype=float)
    out = []
    for k in range(len(table)):
        params = {name: float(table[k, j]) for j, name in enumerate(names)}
        seed = scenario_seed(body.seed, k)
        item: dict[str, Any] = {
            "index": k,
            "seed": seed,
            "params": params,
            "ttc": domain.finite_or_none(domain.ttc_of(params)),
            "exposure_weight": domain.finite_or_none(drawn.weights[k]),
            "risk": None,
        }
        if body.score or body.include_trajectories:
            scenario = domain.build_scenario(params, seed, drawn.lane_width)
            if body.score:
                item["risk"] = domain.jsonable(domain.score_scenario(scenario))
            if body.include_trajectories:
                item["scenario"] = scenario.to_dict()
        out.append(item)
    return {
        "model": model_id,
        "n": len(out),
        "seed": body.seed,
        "sampler": body.sampler,
        "constraints": body.constraints,
        "p_region": domain.jsonable(drawn.p_region),
        "diagnostics": domain.jsonable(drawn.diagnostics),
        "scenarios": out,
    }
