"""Catalogues: persisted, chunked, resumable jobs; status, paging, export, delete."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Literal

from fastapi import APIRouter, BackgroundTasks, Query, Request
from fastapi.responses import FileResponse, Response
from pydantic import Field, WithJsonSchema

from app.db.repository import ORDER_FIELDS
from app.deps import ContextDep, JobsDep
from app.limits import INDEX_MAX
from app.quotas import client_of
from app.routes._download import file_response
from app.schemas import ApiModel, SamplingRequest, schema_enum
from app.services import catalogues as service
from app.statuses import CatalogueStatus
from riskcore.criticality import CLASSES
from sampler.model import SUPPORT_CLASSES
from sampler.scenario import ScenarioRecord

router = APIRouter(prefix="/catalogues", tags=["catalogues"])

MEDIA_TYPES = {
    "jsonl": "application/x-ndjson",
    "csv": "text/csv",
    "parquet": "application/vnd.apache.parquet",
    "xosc": "application/zip",
    "commonroad": "application/zip",
}
SUFFIXES = {"jsonl": "jsonl", "csv": "csv", "parquet": "parquet", "xosc": "zip",
            "commonroad": "commonroad.zip"}


#: a criticality class in a query: the enum in the schema, the check (422 listing them)
#: in ``service.page_filter``
ClassName = Annotated[str, WithJsonSchema({"type": "string", "enum": list(CLASSES)})]
#: a data-support class in a query (issue 25), checked the same way
SupportName = Annotated[str, WithJsonSchema({"type": "string",
                                             "enum": list(SUPPORT_CLASSES)})]


class CatalogueRequest(SamplingRequest):
    n: int = Field(ge=1, description="number of scenarios (≤ SCENGEN_CATALOGUE_N_LIMIT)")
    score: bool = True
    chunk_size: int | None = Field(default=None, ge=1, le=100_000,
                                   description="scenarios per stored chunk (default from "
                                   "the settings)")


class CatalogueCreated(ApiModel):
    id: str
    status: str = Field(description="queued | running | done | failed | cancelled")
    href: str = Field(description="where to poll its status")


class CatalogueItem(ApiModel):
    id: str
    status: str
    n: int
    seed: int
    model: str
    created_at: str


class CatalogueList(ApiModel):
    catalogues: list[CatalogueItem]


@router.post("", status_code=202, response_model=CatalogueCreated,
             summary="Start a catalogue job; answers with its id")
def create_catalogue(body: CatalogueRequest, request: Request, ctx: ContextDep,
                     jobs: JobsDep) -> CatalogueCreated:
    # the request checked first: a bad one is told what is wrong (422), not to wait (429)
    valid = service.validate(ctx, n=body.n, seed=body.seed, constraints=body.constraints,
                             model=body.model, method=body.sampler, score=body.score,
                             chunk_size=body.chunk_size, wagner_scan=body.wagner_scan)
    with jobs.quotas.hold(client_of(request), body.n, ctx.settings) as quota:
        row = service.store(ctx, valid)
    jobs.submit(row.id, quota=quota)
    return CatalogueCreated(id=row.id, status=row.status, href=f"/catalogues/{row.id}")


@router.get("", response_model=CatalogueList, summary="List catalogues")
def list_catalogues(ctx: ContextDep) -> CatalogueList:
    return CatalogueList(catalogues=[
        CatalogueItem(id=r.id, status=r.status, n=r.n, seed=r.seed, model=r.model_id,
                      created_at=r.created_at.isoformat())
        for r in service.list_catalogues(ctx)])


@router.get("/{catalogue_id}", response_model=CatalogueStatus,
            summary="Status, progress, counts, P(A), summary statistics")
def show_catalogue(catalogue_id: str, ctx: ContextDep) -> CatalogueStatus:
    return service.describe(ctx, catalogue_id)


class ScenarioPage(ApiModel):
    catalogue: str
    total: int = Field(description="scenarios matching the filter")
    offset: int
    limit: int
    scenarios: list[ScenarioRecord]


_PAGE_PARAMS = frozenset({"offset", "limit", "order_by", "desc", "class", "support", "risk_min",
                          "risk_max", "ttc_min", "ttc_max"})


@router.get("/{catalogue_id}/scenarios", response_model=ScenarioPage,
            summary="Page through the stored scenarios, ranked and filtered by criticality")
def list_scenarios(
    catalogue_id: str,
    ctx: ContextDep,
    request: Request,
    offset: Annotated[int, Query(ge=0, le=INDEX_MAX)] = 0,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    order_by: Annotated[str, Query(description="sort key: index or a numeric field (ttc, "
                                   "risk, btn, a_req, ttr_true, ...); default btn",
                                   json_schema_extra=schema_enum(ORDER_FIELDS))] = "btn",
    desc: Annotated[bool | None, Query(description="descending (default: true, except for "
                                       "index)")] = None,
    classes: Annotated[list[ClassName] | None, Query(alias="class", description="keep "
                                                     "these classes (repeatable)")] = None,
    supports: Annotated[list[SupportName] | None, Query(
        alias="support", description="keep these data-support classes (repeatable): "
        "inside, near, extrapolated (docs/sampler.md)")] = None,
    risk_min: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    risk_max: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    ttc_min: Annotated[float | None, Query(allow_inf_nan=False)] = None,
    ttc_max: Annotated[float | None, Query(allow_inf_nan=False)] = None,
) -> ScenarioPage:
    """Scenarios of a catalogue, sorted by ``order_by`` (default ``btn``, highest first;
    nulls last, ties by index) and filtered by ``<field>_min``/``<field>_max``
    (inclusive), ``<field>=true|false`` and ``class``."""
    service.get_catalogue(ctx, catalogue_id)  # 404 before the filters' 422
    items = [(k, v) for k, v in request.query_params.multi_items() if k not in _PAGE_PARAMS]
    items += [("support", v) for v in supports or ()]
    flt = dataclasses.replace(service.page_filter(items, classes or (), where="query"),
                              risk_min=risk_min, risk_max=risk_max, ttc_min=ttc_min,
                              ttc_max=ttc_max)
    descending = service.check_order(order_by, desc, where="query")
    page = service.page_scenarios(ctx, catalogue_id, flt, offset, limit, order_by=order_by,
                                  desc=descending)
    return ScenarioPage(catalogue=catalogue_id, total=page.total, offset=offset, limit=limit,
                        scenarios=page.records)


@router.get("/{catalogue_id}/export", summary="Export a finished catalogue",
            response_class=FileResponse, response_model=None)
def export_catalogue(
    catalogue_id: str,
    ctx: ContextDep,
    background: BackgroundTasks,
    format: Annotated[Literal["jsonl", "csv", "parquet", "xosc", "commonroad"],
                      Query()] = "jsonl",
    mode: Annotated[Literal["test", "replay"] | None, Query(
        description="xosc only: test (default; the ego is the system under test) or "
                    "replay (both vehicles scripted)")] = None,
) -> Response:
    return file_response(
        ctx.data_dir, background, f"{catalogue_id}.{SUFFIXES[format]}", MEDIA_TYPES[format],
        lambda out: service.export(ctx, catalogue_id, format, out, mode=mode))


@router.delete("/{catalogue_id}", status_code=204, response_model=None,
               summary="Delete a catalogue (stops its job) and its files")
def delete_catalogue(catalogue_id: str, ctx: ContextDep, jobs: JobsDep) -> Response:
    service.get_catalogue(ctx, catalogue_id)
    jobs.cancel(catalogue_id)
    service.delete(ctx, catalogue_id)
    return Response(status_code=204)
