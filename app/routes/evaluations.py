"""Evaluations (issue 24): a system under test driven through importance-sampled cut-ins,
run as a stored, resumable job; its status and figures, its runs, the failing runs'
export; and the registered systems under test (``GET /suts``)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, BackgroundTasks, Depends, Query, Request
from fastapi.responses import FileResponse, Response
from pydantic import BaseModel, ConfigDict, Field

from app import jsonconv
from app.deps import ContextDep, JobsDep
from app.limits import INDEX_MAX
from app.quotas import client_of
from app.routes._download import file_response
from app.schemas import SEED_MAX, ApiModel, ConstraintText, SutInfo, schema_enum
from app.services import evaluations as service
from app.services import suts
from app.statuses import EvaluationStatus

router = APIRouter(tags=["evaluations"])

MEDIA_TYPES = {"json": "application/json", "xosc": "application/zip",
               "commonroad": "application/zip"}
SUFFIXES = {"json": "json", "xosc": "zip", "commonroad": "commonroad.zip"}


class EvaluationRequest(BaseModel):
    """A campaign: which SUT, over which cut-ins, how many runs or to what precision."""

    model_config = ConfigDict(extra="forbid", strict=True)

    sut: str = Field(max_length=200, description="a registered system under test "
                     "(GET /suts): a built-in or an installed package's entry point in the "
                     "group 'scengen.suts'; never a module path")
    sut_params: dict[str, Any] = Field(default_factory=dict, description="keyword "
                                       "parameters of the SUT (its 'parameters' in GET /suts)")
    model: str = Field(default="default", description="model id ('default': the embedded "
                       "data's model)")
    constraints: list[ConstraintText] = Field(
        default_factory=list, description="restrict the cut-ins to a region (e.g. "
        "'v_ego>25'); default: the model's whole distribution")
    n: int | None = Field(default=None, ge=1, description="exactly this many draws (no "
                          "stop rule)")
    rhw: float = Field(default=service.DEFAULT_RHW, gt=0, lt=10,
                       description="stop when the relative half-width of the 95 % interval "
                       "of P(collision) is at most this (and at least 10 collisions); "
                       "ignored with n")
    max_runs: int | None = Field(default=None, ge=1, description="most draws with the stop "
                                 "rule (default 200,000)")
    seed: int = Field(default=0, ge=0, le=SEED_MAX)
    batch_size: int | None = Field(default=None, ge=1, le=100_000, description="draws per "
                                   "stored chunk (default 2000)")
    settings: dict[str, Any] | None = Field(default=None, description="simulator settings "
                                            "(riskcore.sut.SimSettings fields: dt, "
                                            "a_brake_max, perception_delay, ...)")
    risk: bool = Field(default=False, description="also compute Wagner's TTR risk (r_dep, "
                       "r_ind) of the SUT's own drive in every run: r_dep_peak, r_ind_peak, "
                       "r_dep_time_above (null without it; several times the simulation cost)")
    adapt: Literal["ce", "kernels"] = Field(
        default="ce", description="how later chunks adapt the proposal: 'ce' (the default: "
        "adaptive cross-entropy on the SUT's performance score: pilot chunks, then only the "
        "final stage's runs count) or 'kernels' (Student-t kernels on the collisions so "
        "far; every run counts; its interval undercovers at P near 1e-5, "
        "docs/evaluation.md). The summary reports adapt, pilot_runs and proposal")
    band_step: bool = Field(
        default=False, description="with adapt 'ce': the final stage's band step (each "
        "band part of the proposal gets its own cross-entropy step, and shares move to the "
        "band parts). Measured about 4.6 times fewer runs on an ACC at P(collision) near "
        "1e-5, about 2.5 times more at P near 1e-3 and 1.7 where the bands only slice a "
        "failure set (docs/evaluation.md); the summary reports band_step")
    roulette: float | None = Field(
        default=None, ge=0, le=service.MAX_ROULETTE, description="with adapt 'ce': weight "
        "roulette's factor K (0: off; default 5 with adapt 'ce', 0 with 'kernels'). In the "
        "final stage a draw whose weight p/q is below K times the estimate so far is run "
        "with probability weight / threshold and then weighs the threshold: unbiased, and "
        "the draws the proposal over-samples mostly go unrun; with it on, the final stage "
        "draws the model with share 0.05 instead of 0.15 (stored as final_alpha). "
        "Measured about 1.3 times fewer SUT runs from the roulette and 1.2 times fewer "
        "again from the smaller share, at P(collision) near 1e-5 and near 1e-3 "
        "(docs/evaluation.md, 'Weight roulette', 'A smaller defensive share in the final "
        "stage'). The summary reports roulette, skipped_runs, alpha and final_alpha")


class EvaluationCreated(ApiModel):
    id: str
    status: str = Field(description="queued | running | done | failed | cancelled")
    href: str = Field(description="where to poll its status")


class EvaluationItem(ApiModel):
    id: str
    status: str
    sut: str
    model: str
    seed: int
    constraints: list[str]
    created_at: str


class EvaluationList(ApiModel):
    evaluations: list[EvaluationItem]


class RunPage(ApiModel):
    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="strings")

    evaluation: str
    total: int = Field(description="runs matching the filter")
    offset: int
    limit: int
    runs: list[dict[str, Any]] = Field(description="run, chunk, seed (a string: uint64), "
                                       "the parameters, weight (w/P(B); null until done), "
                                       "weight_raw, log_p, log_q, part, and the outcome "
                                       "fields (collided, impact_speed, r_dep_peak, "
                                       "vs_careful, ...)")


class SutList(ApiModel):
    suts: list[SutInfo]
    conflicts: list[str] = Field(description="entry points left out: their name is taken")


@router.get("/suts", response_model=SutList, tags=["evaluations"],
            summary="The registered systems under test")
def list_suts() -> SutList:
    reg = suts.registry()
    return SutList(suts=[e.info() for e in reg.entries.values()],
                   conflicts=list(reg.conflicts))


@router.post("/evaluations", status_code=202, response_model=EvaluationCreated,
             summary="Start an evaluation of a system under test; answers with its id")
def create_evaluation(body: EvaluationRequest, request: Request, ctx: ContextDep,
                      jobs: JobsDep) -> EvaluationCreated:
    # the request checked first: a bad one is told what is wrong (422), not to wait (429)
    valid = service.validate(ctx, sut=body.sut, sut_params=body.sut_params, model=body.model,
                             constraints=body.constraints, n=body.n, rhw=body.rhw,
                             max_runs=body.max_runs, seed=body.seed,
                             batch_size=body.batch_size, settings=body.settings,
                             risk=body.risk, adapt=body.adapt,
                             band_step=body.band_step, roulette=body.roulette)
    # the client's quota counts the runs it may have queued (app.quotas): n, else max_runs
    # (a stop-rule evaluation holds its max_runs until it ends)
    spec = valid.spec
    if spec.n is not None:
        cost, field, hint = spec.n, "body.n", "ask for fewer"
    else:
        cost, field = spec.max_runs, "body.max_runs"
        hint = (f"give a smaller max_runs (without n an evaluation counts its max_runs, "
                f"{spec.max_runs}) or n")
    with jobs.quotas.hold(client_of(request), cost, ctx.settings, field=field,
                          hint=hint) as quota:
        row = service.store(ctx, valid)
    jobs.submit(row.id, quota=quota)
    return EvaluationCreated(id=row.id, status=row.status, href=f"/evaluations/{row.id}")


@router.get("/evaluations", response_model=EvaluationList, summary="List evaluations")
def list_evaluations(ctx: ContextDep) -> EvaluationList:
    return EvaluationList(evaluations=[
        EvaluationItem(id=r.id, status=r.status, sut=r.sut, model=r.model_id, seed=r.seed,
                       constraints=list((r.spec or {}).get("constraints", [])),
                       created_at=r.created_at.isoformat())
        for r in service.list_all(ctx)])


@router.get("/evaluations/{evaluation_id}", response_model=EvaluationStatus,
            summary="Status, progress and (once done) the collision rate with its intervals")
def show_evaluation(evaluation_id: str, ctx: ContextDep) -> EvaluationStatus:
    return service.describe(ctx, evaluation_id)


_RANGE_DOCS = {"impact_speed": "impact speed (m/s, 0 without a collision)",
               "r_dep_peak": "peak r_dep of the SUT (0..1)",
               "min_gap": "smallest gap to the cutter (m)",
               "min_ttc": "smallest time to collision (s)"}
_FLAG_DOCS = {"collided": "the SUT hit the cutter",
              "must_avoid": "the regulation says the cut-in must be avoided (UN R157 "
              "5.2.5.2: the TTC when the cutter is 0.3 m into the lane exceeds the value "
              "for its closing speed; docs/systems.md)",
              "violation": "must_avoid and the SUT collided"}
#: the filter parameters of ``/runs`` and ``/export`` (declared in ``run_filter_params``)
FILTER_PARAMS = frozenset([f"{f}_{b}" for f in service.RANGE_FIELDS for b in ("min", "max")]
                          + list(service.FLAG_FIELDS) + ["vs_careful"])
_Bound = Annotated[float | None, Query(allow_inf_nan=False)]


def run_filter_params(
    request: Request,
    impact_speed_min: Annotated[float | None, Query(
        allow_inf_nan=False, description=f"inclusive bounds on the {_RANGE_DOCS['impact_speed']}"
        "; finite numbers in ASCII digits (leave a side open rather than inf)")] = None,
    impact_speed_max: _Bound = None,
    r_dep_peak_min: Annotated[float | None, Query(
        allow_inf_nan=False, description=f"inclusive bounds on the {_RANGE_DOCS['r_dep_peak']}"
        )] = None,
    r_dep_peak_max: _Bound = None,
    min_gap_min: Annotated[float | None, Query(
        allow_inf_nan=False, description=f"inclusive bounds on the {_RANGE_DOCS['min_gap']}"
        )] = None,
    min_gap_max: _Bound = None,
    min_ttc_min: Annotated[float | None, Query(
        allow_inf_nan=False, description=f"inclusive bounds on the {_RANGE_DOCS['min_ttc']}"
        " (null when the gap opens: such runs never match a bound)")] = None,
    min_ttc_max: _Bound = None,
    collided: Annotated[bool | None, Query(description=_FLAG_DOCS["collided"])] = None,
    must_avoid: Annotated[bool | None, Query(description=_FLAG_DOCS["must_avoid"])] = None,
    violation: Annotated[bool | None, Query(description=_FLAG_DOCS["violation"])] = None,
    vs_careful: Annotated[list[Literal["worse", "same", "better"]] | None, Query(
        description="keep runs the SUT did worse / the same / better than the R157 "
                    "careful driver (repeatable)")] = None,
) -> service.RunFilter | None:
    """The filters given (None: no filter at all). The typed parameters above are the
    OpenAPI declaration; the raw values are parsed by ``service.run_filter`` (ASCII
    finite numbers, true|false), which also names any parameter the route does not take."""
    items = [(k, v) for k, v in request.query_params.multi_items()
             if k in FILTER_PARAMS and k != "vs_careful"]
    if not items and not vs_careful:
        return None
    return service.run_filter(items, vs_careful or (), where="query")


RunFilterDep = Annotated[service.RunFilter | None, Depends(run_filter_params)]


def reject_unknown(request: Request, route_params: frozenset[str]) -> None:
    """A 422 naming the first query parameter the route does not take."""
    for key in request.query_params:
        if key not in route_params and key not in FILTER_PARAMS:
            # parse_filters words the message (the filters and their forms)
            service.run_filter([(key, request.query_params[key])], where="query")


_PAGE_PARAMS = frozenset({"offset", "limit", "order_by", "desc"})


@router.get("/evaluations/{evaluation_id}/runs", response_model=RunPage,
            summary="Page through the runs the SUT drove, ranked and filtered")
def list_runs(
    evaluation_id: str,
    ctx: ContextDep,
    request: Request,
    flt: RunFilterDep,
    offset: Annotated[int, Query(ge=0, le=INDEX_MAX)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    order_by: Annotated[str, Query(description="run, impact_speed (default), r_dep_peak, "
                                   "min_gap, min_ttc or weight",
                                   json_schema_extra=schema_enum(service.ORDER_FIELDS))
                        ] = "impact_speed",
    desc: Annotated[bool | None, Query(description="descending (default: true, except for "
                                       "run)")] = None,
) -> RunPage:
    """Runs sorted by ``order_by`` (nulls last, ties by run) and filtered by
    ``<field>_min``/``<field>_max`` (impact_speed, r_dep_peak, min_gap, min_ttc),
    ``collided|must_avoid|violation=true|false`` and ``vs_careful``; any other query
    parameter is a 422 naming it."""
    service.get(ctx, evaluation_id)  # 404 before the filters' 422
    reject_unknown(request, _PAGE_PARAMS)
    descending = service.check_order(order_by, desc, where="query")
    total, runs = service.page_runs(ctx, evaluation_id, flt or service.RunFilter(), offset,
                                    limit, order_by=order_by, desc=descending)
    return RunPage(evaluation=evaluation_id, total=total, offset=offset, limit=limit,
                   runs=jsonconv.encode(runs))


@router.get("/evaluations/{evaluation_id}/export", response_class=FileResponse,
            response_model=None,
            summary="Export the failing (or the filtered) runs of a finished evaluation")
def export_evaluation(
    evaluation_id: str,
    ctx: ContextDep,
    request: Request,
    background: BackgroundTasks,
    flt: RunFilterDep,
    format: Annotated[Literal["json", "xosc", "commonroad"], Query()] = "json",
) -> Response:
    """The runs matching the filters of ``/runs`` (without any: the collided runs), highest
    impact speed first, each rebuilt from its parameter vector: ``json`` (the summary and
    each run's record with its concrete scenario), ``xosc`` (OpenSCENARIO 1.2 in test mode:
    the ego is the system under test) or ``commonroad`` (zip). Any other query parameter
    is a 422 naming it."""
    service.get(ctx, evaluation_id)  # 404 before the filters' 422
    reject_unknown(request, frozenset({"format"}))
    name = "failures" if flt is None else "runs"
    return file_response(
        ctx.data_dir, background, f"{evaluation_id}-{name}.{SUFFIXES[format]}",
        MEDIA_TYPES[format], lambda out: service.export(ctx, evaluation_id, format, out,
                                                        flt=flt))


@router.delete("/evaluations/{evaluation_id}", status_code=204, response_model=None,
               summary="Delete an evaluation (stops its job) and its runs")
def delete_evaluation(evaluation_id: str, ctx: ContextDep, jobs: JobsDep) -> Response:
    service.get(ctx, evaluation_id)
    jobs.cancel(evaluation_id)
    service.delete(ctx, evaluation_id)
    return Response(status_code=204)
