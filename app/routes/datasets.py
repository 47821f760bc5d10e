"""Datasets: the embedded real data first, uploads, and their cut-in parameter tables."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Query, UploadFile
from fastapi.responses import Response
from pydantic import Field

from app import jsonconv
from app.db.models import DatasetRow
from app.deps import ContextDep
from app.limits import INDEX_MAX
from app.rates import ExposureInfo
from app.schemas import ApiModel
from app.services import datasets as datasets_service

router = APIRouter(prefix="/datasets", tags=["datasets"])

class DatasetInfo(ApiModel):
    id: str
    name: str
    kind: str = Field(description="embedded | highd | egocentric")
    embedded: bool
    n_cutins: int
    data_hash: str = Field(description="sha256 of the parameter table")
    report: dict[str, Any] = Field(description="counts, events left out and why, source")
    exposure: ExposureInfo | None = Field(
        default=None, description="driving in which the cut-ins were recorded (highD: "
        "vehicle-hours and vehicle-km summed over the tracked vehicles; the embedded TNO "
        "data: 63 hours); models fitted on the dataset carry it")
    created_at: str


class DatasetList(ApiModel):
    datasets: list[DatasetInfo]


class ParameterPage(ApiModel):
    dataset: str
    total: int
    offset: int
    limit: int
    columns: list[str]
    rows: list[dict[str, Any]] = Field(description="one object per cut-in")


def dataset_view(row: DatasetRow) -> DatasetInfo:
    exposure = datasets_service.dataset_exposure(row)
    return DatasetInfo(id=row.id, name=row.name, kind=row.kind, embedded=row.embedded,
                       n_cutins=row.n_cutins, data_hash=row.data_hash,
                       report=jsonconv.encode(row.report), exposure=exposure,
                       created_at=row.created_at.isoformat())


@router.get("", response_model=DatasetList,
            summary="List datasets (the embedded real data first)")
def list_datasets(ctx: ContextDep) -> DatasetList:
    return DatasetList(datasets=[dataset_view(r) for r in datasets_service.list_datasets(ctx)])


@router.get("/{dataset_id}", response_model=DatasetInfo, summary="One dataset")
def show_dataset(dataset_id: str, ctx: ContextDep) -> DatasetInfo:
    return dataset_view(datasets_service.get_dataset(ctx, dataset_id))


@router.get("/{dataset_id}/parameters", summary="The cut-in parameter table, paged (JSON: "
            "ParameterPage; CSV: the page, total in X-Total-Count)", response_model=None,
            responses={200: {"model": ParameterPage,
                             "content": {"text/csv": {"schema": {"type": "string"}}}}})
def parameter_table(
    dataset_id: str,
    ctx: ContextDep,
    offset: Annotated[int, Query(ge=0, le=INDEX_MAX)] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 100,
    format: Annotated[Literal["json", "csv"], Query()] = "json",
) -> ParameterPage | Response:
    table = datasets_service.parameter_table(ctx, dataset_id)
    page = table.iloc[offset:offset + limit]
    if format == "csv":
        return Response(page.to_csv(index=False), media_type="text/csv",
                        headers={"X-Total-Count": str(len(table))})
    return ParameterPage(dataset=dataset_id, total=len(table), offset=offset, limit=limit,
                         columns=[str(c) for c in table.columns],
                         rows=jsonconv.encode(page.to_dict(orient="records")))


@router.post("", status_code=201, response_model=DatasetInfo,
             summary="Upload a dataset (highD recording files or one ego-centric CSV/Parquet "
             "file)")
def upload_dataset(
    ctx: ContextDep,
    kind: Annotated[Literal["highd", "egocentric"], Form()],
    files: Annotated[list[UploadFile], File()],
    name: Annotated[str | None, Form(max_length=200)] = None,
    allow_implausible: Annotated[bool, Form(
        description="store the data even when its medians look like wrong units (speeds in "
        "km/h, positions in mm); the report lists the warnings")] = False,
) -> DatasetInfo:
    row = datasets_service.upload(ctx, kind, files, name, allow_implausible)
    return dataset_view(row)
