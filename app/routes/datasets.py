"""Datasets: the embedded real data first, uploads, and their cut-in parameter tables."""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import re
import shutil
import uuid
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Query, UploadFile
from fastapi.responses import Response
from pydantic import Field

from app import domain, jsonconv
from app.db import repository as repo
from app.db.models import DatasetRow
from app.deps import ContextDep, SessionDep
from app.errors import InvalidInput, PayloadTooLarge
from app.limits import INDEX_MAX
from app.rates import ExposureInfo
from app.schemas import ApiModel
from datasets import implausible
from sampler.rates import tno_exposure

router = APIRouter(prefix="/datasets", tags=["datasets"])

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,200}$")
_COPY_BLOCK = 1024 * 1024


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
    exposure = (row.report or {}).get("exposure")
    if exposure is None and row.embedded:
        exposure = tno_exposure(row.n_cutins).to_dict()
    return DatasetInfo(id=row.id, name=row.name, kind=row.kind, embedded=row.embedded,
                       n_cutins=row.n_cutins, data_hash=row.data_hash,
                       report=jsonconv.encode(row.report), exposure=exposure,
                       created_at=row.created_at.isoformat())


@router.get("", response_model=DatasetList,
            summary="List datasets (the embedded real data first)")
def list_datasets(session: SessionDep) -> DatasetList:
    return DatasetList(datasets=[dataset_view(r) for r in repo.list_datasets(session)])


@router.get("/{dataset_id}", response_model=DatasetInfo, summary="One dataset")
def show_dataset(dataset_id: str, session: SessionDep) -> DatasetInfo:
    return dataset_view(repo.get_dataset(session, dataset_id))


@router.get("/{dataset_id}/parameters", summary="The cut-in parameter table, paged (JSON: "
            "ParameterPage; CSV: the page, total in X-Total-Count)", response_model=None,
            responses={200: {"model": ParameterPage,
                             "content": {"text/csv": {"schema": {"type": "string"}}}}})
def parameter_table(
    dataset_id: str,
    ctx: ContextDep,
    session: SessionDep,
    offset: Annotated[int, Query(ge=0, le=INDEX_MAX)] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 100,
    format: Annotated[Literal["json", "csv"], Query()] = "json",
) -> ParameterPage | Response:
    row = repo.get_dataset(session, dataset_id)
    table = ctx.dataset_table(row)
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
    limit = ctx.settings.upload_limit_bytes
    dataset_id = repo.new_id("ds")
    staging = ctx.data_dir / "tmp" / f"upload-{uuid.uuid4().hex}"
    raw = staging / "raw"
    raw.mkdir(parents=True)
    try:
        paths = _save_uploads(files, raw, limit)
        check_expanded_size(paths, ctx.settings.upload_expanded_limit_bytes)
        table, report = domain.dataset_from_files(kind, paths)
        if len(table) == 0:
            raise InvalidInput("no cut-ins found in the uploaded files", field="body.files")
        problems = implausible(table)
        if problems and not allow_implausible:
            raise InvalidInput("implausible values, wrong units? " + "; ".join(problems)
                               + " (send allow_implausible=true to store it anyway)",
                               field="body.files")
        report["plausibility_warnings"] = problems
        data_hash = domain.table_hash(table)
        table.to_parquet(staging / "table.parquet", index=False)
        final = ctx.data_dir / "datasets" / dataset_id
        final.parent.mkdir(parents=True, exist_ok=True)
        staging.replace(final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    try:
        with ctx.db.session() as s:
            row = DatasetRow(id=dataset_id, name=name or paths[0].name, kind=kind,
                             embedded=False, data_hash=data_hash, n_cutins=len(table),
                             table_path=f"datasets/{dataset_id}/table.parquet",
                             report=jsonconv.encode(report))
            s.add(row)
    except BaseException:
        shutil.rmtree(final, ignore_errors=True)
        raise
    return dataset_view(row)


def _open_decompressed(path: Path) -> io.BufferedIOBase | None:
    """The decompressed stream of a compressed file the readers accept (else None)."""
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return gzip.open(path, "rb")
    if suffix == ".bz2":
        return bz2.open(path, "rb")
    if suffix == ".xz":
        return lzma.open(path, "rb")
    return None


def check_expanded_size(paths: list[Path], limit: int) -> None:
    """413 when the uploaded files would be larger than ``limit`` bytes once decompressed
    (a small .csv.gz can expand to gigabytes): compressed CSVs are streamed through their
    decompressor and counted, Parquet files count their row groups' uncompressed size."""
    total = 0

    def add(n: int) -> None:
        nonlocal total
        total += n
        if total > limit:
            raise PayloadTooLarge(f"upload larger than the limit of {limit} bytes once "
                                  "decompressed (SCENGEN_UPLOAD_EXPANDED_LIMIT_BYTES)",
                                  field="body.files")

    for path in paths:
        if path.suffix.lower() in (".gz", ".bz2", ".xz"):
            try:
                stream = _open_decompressed(path)
                assert stream is not None
                with stream as fh:
                    while block := fh.read(_COPY_BLOCK):
                        add(len(block))
            except (OSError, EOFError, lzma.LZMAError) as exc:
                raise InvalidInput(f"{path.name}: not a readable {path.suffix} file ({exc})",
                                   field="body.files") from None
        elif path.suffix.lower() in (".parquet", ".pq"):
            add(max(path.stat().st_size, _parquet_uncompressed(path)))
        else:
            add(path.stat().st_size)


def _parquet_uncompressed(path: Path) -> int:
    import pyarrow.parquet as pq

    try:
        meta = pq.ParquetFile(path).metadata
    except Exception:  # not Parquet: the reader says so with its own message
        return 0
    return sum(meta.row_group(k).total_byte_size for k in range(meta.num_row_groups))


def _save_uploads(files: list[UploadFile], folder: Path, limit: int) -> list[Path]:
    if not files:
        raise InvalidInput("no file uploaded", field="body.files")
    total = 0
    paths: list[Path] = []
    for i, upload in enumerate(files):
        name = Path(upload.filename or "").name
        if not _SAFE_NAME.match(name):
            raise InvalidInput(f"file name {upload.filename!r} is not allowed (letters, "
                               "digits, '.', '_', '-')", field=f"body.files.{i}")
        target = folder / name
        if target.exists():
            raise InvalidInput(f"file {name!r} uploaded twice", field=f"body.files.{i}")
        with open(target, "wb") as out:
            while block := upload.file.read(_COPY_BLOCK):
                total += len(block)
                if total > limit:
                    raise PayloadTooLarge(f"upload larger than the limit of {limit} bytes",
                                          field="body.files")
                out.write(block)
        paths.append(target)
    return paths
