"""CSV and Parquet exports: one flat row per scenario (``scenario_row``), streamed.

The first row fixes the columns (``index`` first, then the row's columns). A later row
may leave an extra column empty but may not bring a new one: the writers are streaming and
cannot go back to widen the header, so that is an error naming the column.

Parquet column types: the known columns have fixed types (``index``, ``seed``,
``n_steps``, ``n_objects``: int64; the parameters, the derived floats, ``exposure_weight``
and the criticality record's float fields: float64; its bool fields: bool; its text
fields and ``error``: string). Any other column
takes its type from the first row group: bool if it holds only booleans, string if only
strings, int64 for an integer ``scenario_id``, float64 for numbers (and for a column that
is empty in the whole first row group; string for an empty ``scenario_id``). A later value
of another kind is an error naming the column.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

import pyarrow as pa
import pyarrow.parquet as pq

from app.exports._common import ExportError, Row, dumps
from datasets import PARAM_NAMES
from riskcore import ConcreteScenario
from riskcore.criticality import CRITICALITY_FIELDS

Item = tuple[int, ConcreteScenario, Mapping[str, Any], Row]

#: Rows per Parquet row group (and per batch held in memory).
ROW_GROUP_SIZE = 2048

#: Metadata key of the manifest (JSON) in the Parquet file.
PARQUET_MANIFEST_KEY = b"scengen.manifest"

_INT_COLUMNS = frozenset({"index", "seed", "n_steps", "n_objects"})
_FLOAT_COLUMNS = frozenset({
    *PARAM_NAMES, "ttc", "duration", "dt", "exposure_weight", "support_distance",
    "support_excess",
    *(name for name, spec in CRITICALITY_FIELDS.items() if spec.kind == "float"),
})
_BOOL_COLUMNS = frozenset(name for name, spec in CRITICALITY_FIELDS.items()
                          if spec.kind == "bool")
_STRING_COLUMNS = frozenset({
    "error", "support", *(name for name, spec in CRITICALITY_FIELDS.items() if spec.kind == "str")})


def _with_index(index: int, row: Row) -> Row:
    out: Row = {"index": index}
    out.update(row)
    return out


def _check_columns(columns: Sequence[str], row: Row, index: int) -> None:
    if len(row) > len(columns) or any(key not in columns for key in row):
        known = set(columns)
        new = [key for key in row if key not in known]
        raise ExportError(
            f"item {index}: column(s) {', '.join(map(repr, new))} not in the first row; every "
            "summary of a catalogue must have the same keys (use None for missing values)"
        )


def _csv_cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # shortest round-trip form; inf, -inf, nan
    return value


class CsvRowWriter:
    """Streams rows to an open text file: header from the first row, then one line each."""

    def __init__(self, fh: TextIO, lead: Sequence[str] = ()) -> None:
        self._writer = csv.writer(fh, lineterminator="\n")
        self._lead = tuple(lead)
        self.columns: list[str] | None = None

    def write(self, index: int, row: Row, lead_values: Sequence[Any] = ()) -> None:
        """Write ``row`` (``index`` goes first, after the ``lead`` columns)."""
        full = _with_index(index, row)
        if self.columns is None:
            self.columns = list(full)
            self._writer.writerow([*self._lead, *self.columns])
        else:
            _check_columns(self.columns, full, index)
        self._writer.writerow(
            [*lead_values, *(_csv_cell(full.get(c)) for c in self.columns)]
        )


def write_csv(items: Iterator[Item], path: Path) -> None:
    """Header line plus one line per item; ``\\n`` line ends, minimal RFC 4180 quoting."""
    with path.open("w", encoding="utf-8", newline="") as fh:
        writer = CsvRowWriter(fh)
        for index, _scenario, _summary, row in items:
            writer.write(index, row)


def _kind(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int | float):
        return "number"
    return "string"


def _arrow_type(column: str, values: Sequence[Any]) -> pa.DataType:
    if column in _INT_COLUMNS:
        return pa.int64()
    if column in _FLOAT_COLUMNS:
        return pa.float64()
    if column in _STRING_COLUMNS:
        return pa.string()
    if column in _BOOL_COLUMNS:
        return pa.bool_()
    kinds = {_kind(v) for v in values} - {None}
    if not kinds:
        return pa.string() if column == "scenario_id" else pa.float64()
    if len(kinds) > 1:
        raise ExportError(
            f"column {column!r}: mixes {' and '.join(sorted(k for k in kinds if k))} values; "
            "a column must hold one kind"
        )
    kind = kinds.pop()
    if kind == "bool":
        return pa.bool_()
    if kind == "string":
        return pa.string()
    if column == "scenario_id" and all(isinstance(v, int) for v in values if v is not None):
        return pa.int64()
    return pa.float64()


def _expected_kind(dtype: pa.DataType) -> str:
    if pa.types.is_boolean(dtype):
        return "bool"
    if pa.types.is_string(dtype):
        return "string"
    return "number"


def _column_array(
    column: str, values: list[Any], dtype: pa.DataType, first_index: int
) -> pa.Array:
    expected = _expected_kind(dtype)
    for offset, value in enumerate(values):
        kind = _kind(value)
        if kind is not None and kind != expected:
            raise ExportError(
                f"item {first_index + offset}: column {column!r} holds {expected} values, "
                f"got {value!r}"
            )
        if pa.types.is_integer(dtype) and isinstance(value, float):
            raise ExportError(
                f"item {first_index + offset}: column {column!r} holds integers, got {value!r}"
            )
    return pa.array(values, type=dtype)


def write_parquet(items: Iterator[Item], manifest: Mapping[str, Any], path: Path) -> None:
    """Rows in row groups of ``ROW_GROUP_SIZE``; manifest in the key-value metadata."""
    columns: list[str] | None = None
    schema: pa.Schema | None = None
    writer: pq.ParquetWriter | None = None
    batch: list[Row] = []
    batch_start = 0

    def flush() -> None:
        nonlocal schema, writer
        if not batch:
            return
        assert columns is not None
        if schema is None:
            fields = [
                pa.field(c, _arrow_type(c, [r.get(c) for r in batch])) for c in columns
            ]
            schema = pa.schema(fields, metadata={PARQUET_MANIFEST_KEY: dumps(dict(manifest))})
            writer = pq.ParquetWriter(path, schema, compression="zstd")
        arrays = [
            _column_array(f.name, [r.get(f.name) for r in batch], f.type, batch_start)
            for f in schema
        ]
        assert writer is not None
        writer.write_table(pa.Table.from_arrays(arrays, schema=schema),
                           row_group_size=ROW_GROUP_SIZE)
        batch.clear()

    try:
        for index, _scenario, _summary, row in items:
            full = _with_index(index, row)
            if columns is None:
                columns = list(full)
            else:
                _check_columns(columns, full, index)
            if not batch:
                batch_start = index
            batch.append(full)
            if len(batch) >= ROW_GROUP_SIZE:
                flush()
        flush()
    finally:
        if writer is not None:
            writer.close()
