"""Datasets for the service: the embedded TNO table, uploaded files, content hashes."""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import pandas as pd

from app import jsonconv
from app.errors import InvalidInput
from datasets import DatasetError, default_parameter_table, extract_cutins
from datasets import embedded_source_hash as embedded_source_hash_of_datasets
from sampler.rates import highd_exposure

__all__ = ["DATASET_KINDS", "dataset_from_files", "embedded_parameter_table",
           "embedded_source_hash", "options_hash", "table_hash"]

DATASET_KINDS = ("highd", "egocentric")

def embedded_parameter_table() -> pd.DataFrame:
    """The cut-in parameter table of the embedded TNO data (one row per cut-in)."""
    return default_parameter_table()


def embedded_source_hash() -> str:
    """sha256 of the embedded events file and of the extraction code: the key of the
    cached embedded parameter table (extraction takes tens of seconds)."""
    return embedded_source_hash_of_datasets()


def options_hash(options: Mapping[str, Any]) -> str:
    """sha256 of model options (the key of a cached default model)."""
    text = json.dumps(jsonconv.encode(dict(options)), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def table_hash(table: pd.DataFrame) -> str:
    """sha256 of a parameter table's content (columns, order, values): the data hash."""
    buf = io.StringIO()
    table.to_csv(buf, index=False, float_format="%.17g")
    return hashlib.sha256(buf.getvalue().encode()).hexdigest()


def dataset_from_files(kind: str, paths: Sequence[Path]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Read uploaded files of one dataset and extract its cut-in parameter table.

    ``kind`` is ``highd`` (a recording's ``*_tracks.csv``, ``*_tracksMeta.csv`` and
    ``*_recordingMeta.csv``) or ``egocentric`` (one CSV or Parquet file). Returns the table
    and a report (counts, dropped events). Bad files raise InvalidInput.
    """
    if kind not in DATASET_KINDS:
        raise InvalidInput(f"unknown dataset kind {kind!r}; choose one of "
                           f"{', '.join(DATASET_KINDS)}", field="body.kind")
    fmt: Literal["highd", "egocentric"] = "egocentric" if kind == "egocentric" else "highd"
    if fmt == "egocentric":
        if len(paths) != 1:
            raise InvalidInput(f"the ego-centric format is one CSV or Parquet file, got "
                               f"{len(paths)} files", field="body.files")
        target: Path = paths[0]
    else:
        folder = {p.parent for p in paths}
        if len(folder) != 1:
            raise InvalidInput("highD files must be uploaded together", field="body.files")
        target = folder.pop()
    try:
        result = extract_cutins(target, fmt)
    except (DatasetError, ValueError, OSError, KeyError) as exc:
        # a malformed upload (pyarrow and pandas raise their own ValueError/OSError kinds)
        raise InvalidInput(f"{kind} upload: {exc}", field="body.files") from None
    skipped = [{"event_id": e, "reason": r} for e, r in result.skipped]
    report = {"n_cutins": len(result.table), "n_skipped": len(skipped),
              "skipped": skipped[:200], "files": [p.name for p in paths]}
    if result.exposure is not None:  # highD: vehicle-hours and vehicle-km (issue 12)
        report["exposure"] = highd_exposure(result.exposure, len(result.table)).to_dict()
    return result.table, report
