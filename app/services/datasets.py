"""Datasets: uploads (saved, size-checked, extracted, checked for plausibility, stored),
their parameter tables and exposure.

``upload`` takes the uploaded files as (name, binary stream) pairs (``UploadedFile``: what
FastAPI's ``UploadFile`` is), so it does not depend on the web framework. A failed upload
leaves nothing behind: the files are staged under ``<data_dir>/tmp`` and moved into
``<data_dir>/datasets/<id>`` only once the table is extracted and checked.
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import re
import shutil
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any, BinaryIO, Protocol

import pandas as pd

from app import domain, jsonconv
from app.context import ServiceContext
from app.db import repository as repo
from app.db.models import DatasetRow
from app.errors import InvalidInput, PayloadTooLarge
from datasets import implausible
from sampler.rates import tno_exposure

__all__ = ["UploadedFile", "check_expanded_size", "dataset_exposure", "get_dataset",
           "list_datasets", "parameter_table", "upload"]

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,200}$")
_COPY_BLOCK = 1024 * 1024


class UploadedFile(Protocol):
    """One uploaded file: its name as the client gave it and its content."""

    @property
    def filename(self) -> str | None: ...
    @property
    def file(self) -> BinaryIO: ...


def dataset_exposure(row: DatasetRow) -> dict[str, Any] | None:
    """The driving a dataset's cut-ins were recorded in (highD uploads: from the upload's
    report; the embedded TNO data: its 63 hours); None when unknown."""
    exposure: dict[str, Any] | None = (row.report or {}).get("exposure")
    if exposure is None and row.embedded:
        exposure = tno_exposure(row.n_cutins).to_dict()
    return exposure


def list_datasets(ctx: ServiceContext) -> list[DatasetRow]:
    """The stored datasets, the embedded real data first."""
    with ctx.db.read_session() as s:
        return list(repo.list_datasets(s))


def get_dataset(ctx: ServiceContext, dataset_id: str) -> DatasetRow:
    """A stored dataset (404 for an unknown id)."""
    with ctx.db.read_session() as s:
        return repo.get_dataset(s, dataset_id)


def parameter_table(ctx: ServiceContext, dataset_id: str) -> pd.DataFrame:
    """A stored dataset's cut-in parameter table."""
    return ctx.dataset_table(get_dataset(ctx, dataset_id))


def upload(ctx: ServiceContext, kind: str, files: Sequence[UploadedFile],
           name: str | None = None, allow_implausible: bool = False) -> DatasetRow:
    """Store an uploaded dataset (highD recording files or one ego-centric CSV/Parquet
    file) under a new id: the files within the size limits (413 otherwise), its cut-in
    table extracted and, unless ``allow_implausible``, free of values that look like wrong
    units (422 naming ``body.files``)."""
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
    return row


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


def _save_uploads(files: Sequence[UploadedFile], folder: Path, limit: int) -> list[Path]:
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
