"""Reading and writing the service's records. Functions take an open Session; the caller
owns the transaction (``Database.session()``), so a chunk is stored all-or-nothing.

Files (parameter tables, chunk trajectories) live under the data dir and are referenced by
relative paths; they are written under a temporary name and renamed into place *before*
the transaction that references them commits, so a crash never leaves a reference to a
missing or half-written file.
"""

from __future__ import annotations

import io
import math
import shutil
import uuid
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import delete, func, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.atomic import write_atomic
from app.db import chunkfile
from app.db.models import CatalogueRow, ChunkRow, DatasetRow, ModelRow, ScenarioRow, utcnow
from app.errors import NotFound

ACTIVE = ("queued", "running")


def new_id(prefix: str) -> str:
    return f"{prefix}-{uuid.uuid4().hex[:12]}"


# --------------------------------------------------------------------------- datasets
def get_dataset(session: Session, dataset_id: str,
                field: str = "path.dataset_id") -> DatasetRow:
    row = session.get(DatasetRow, dataset_id)
    if row is None:
        raise NotFound(f"dataset {dataset_id!r} not found", field=field)
    return row


def list_datasets(session: Session) -> list[DatasetRow]:
    stmt = select(DatasetRow).order_by(DatasetRow.embedded.desc(), DatasetRow.created_at,
                                       DatasetRow.id)
    return list(session.scalars(stmt))


# --------------------------------------------------------------------------- models
def get_model(session: Session, model_id: str, field: str = "path.model_id") -> ModelRow:
    row = session.get(ModelRow, model_id)
    if row is None:
        raise NotFound(f"model {model_id!r} not found", field=field)
    return row


def list_models(session: Session) -> list[ModelRow]:
    stmt = select(ModelRow).order_by(ModelRow.is_default.desc(), ModelRow.created_at,
                                     ModelRow.id)
    return list(session.scalars(stmt))


# --------------------------------------------------------------------------- catalogues
def get_catalogue(session: Session, catalogue_id: str) -> CatalogueRow:
    row = session.get(CatalogueRow, catalogue_id)
    if row is None:
        raise NotFound(f"catalogue {catalogue_id!r} not found", field="path.catalogue_id")
    return row


def list_catalogues(session: Session) -> list[CatalogueRow]:
    return list(session.scalars(select(CatalogueRow).order_by(CatalogueRow.created_at)))


def stored_chunk_indices(session: Session, catalogue_id: str) -> set[int]:
    stmt = select(ChunkRow.chunk_index).where(ChunkRow.catalogue_id == catalogue_id)
    return set(session.scalars(stmt))


def store_chunk(session: Session, data_dir: Path, catalogue_id: str, index: int,
                rows: Sequence[dict[str, Any]], blob: bytes | None, sha256: str | None,
                diagnostics: dict[str, Any]) -> bool:
    """Store one finished chunk: its file first, then its rows in this transaction.

    Returns False (and changes nothing) when the chunk is already stored or the catalogue
    is gone. The chunk file's content is a function of (spec, index), so rewriting it for
    a chunk that was computed twice writes the same bytes.
    """
    if session.get(CatalogueRow, catalogue_id) is None:
        return False
    if index in stored_chunk_indices(session, catalogue_id):
        return False
    rel = None
    if blob is not None:
        rel = chunkfile.relative_path(catalogue_id, index)
        write_atomic(data_dir / rel, blob)
    try:
        with session.begin_nested():
            session.add(ChunkRow(catalogue_id=catalogue_id, chunk_index=index,
                                 n_scenarios=len(rows), file_path=rel, sha256=sha256,
                                 diagnostics=diagnostics, stat_values=_stat_blob(rows),
                                 stat_columns=list(STAT_COLUMNS)))
            session.flush()
            if rows:
                session.execute(insert(ScenarioRow),
                                [{**r, "catalogue_id": catalogue_id} for r in rows])
    except IntegrityError:
        return False  # another runner stored it first; same content by construction
    session.execute(update(CatalogueRow).where(CatalogueRow.id == catalogue_id)
                    .values(updated_at=utcnow()))
    return True


def chunk_counts(session: Session, catalogue_id: str) -> tuple[int, int]:
    """(chunks stored, scenarios stored) of a catalogue, from its chunk rows."""
    n, total = session.execute(
        select(func.count(ChunkRow.id), func.coalesce(func.sum(ChunkRow.n_scenarios), 0))
        .where(ChunkRow.catalogue_id == catalogue_id)).one()
    return int(n), int(total)


def count_scenarios(session: Session, catalogue_id: str) -> int:
    stmt = select(func.count()).select_from(ScenarioRow).where(
        ScenarioRow.catalogue_id == catalogue_id)
    return int(session.scalar(stmt) or 0)


def _criticality_kinds() -> dict[str, str]:
    """Criticality field name -> kind (float|bool|str), from riskcore's CRITICALITY_FIELDS."""
    from riskcore.criticality import CRITICALITY_FIELDS

    return {name: spec.kind for name, spec in CRITICALITY_FIELDS.items()}


def _column(name: str) -> Any:
    return ScenarioRow.class_ if name == "class" else getattr(ScenarioRow, name)


#: the numeric columns a scenario page may be sorted by and filtered on (ranges)
RANGE_FIELDS: tuple[str, ...] = ("ttc", "risk", "exposure_weight", *(
    name for name, kind in _criticality_kinds().items() if kind == "float"))
#: the yes/no columns a page may be filtered on
FLAG_FIELDS: tuple[str, ...] = tuple(
    name for name, kind in _criticality_kinds().items() if kind == "bool")
#: what ``order_by`` accepts
ORDER_FIELDS: tuple[str, ...] = ("index", *RANGE_FIELDS)


@dataclass(frozen=True)
class ScenarioFilter:
    """Filters of a scenario page: inclusive ranges of numeric columns, yes/no columns,
    the classes, the data-support classes. ``risk_min`` ... ``ttc_max`` are kept as shorthands."""

    risk_min: float | None = None
    risk_max: float | None = None
    ttc_min: float | None = None
    ttc_max: float | None = None
    ranges: tuple[tuple[str, float | None, float | None], ...] = ()
    flags: tuple[tuple[str, bool], ...] = ()
    classes: tuple[str, ...] = ()
    #: data-support classes to keep (inside / near / extrapolated; issue 25)
    supports: tuple[str, ...] = ()

    def apply(self, stmt: Any) -> Any:
        ranges = [("risk", self.risk_min, self.risk_max), ("ttc", self.ttc_min, self.ttc_max),
                  *self.ranges]
        for name, lo, hi in ranges:
            col = _column(name)
            if lo is not None:
                stmt = stmt.where(col >= lo)
            if hi is not None:
                stmt = stmt.where(col <= hi)
        for name, value in self.flags:
            stmt = stmt.where(_column(name).is_(value))
        if self.classes:
            stmt = stmt.where(ScenarioRow.class_.in_(self.classes))
        if self.supports:
            stmt = stmt.where(ScenarioRow.support.in_(self.supports))
        return stmt


def page_scenarios(session: Session, catalogue_id: str, flt: ScenarioFilter, offset: int,
                   limit: int, order_by: str = "index",
                   desc: bool = False) -> tuple[int, list[ScenarioRow]]:
    """One page of a catalogue's scenarios, filtered and sorted (nulls last, then by
    index; +inf sorts above every finite value)."""
    base = flt.apply(select(ScenarioRow).where(ScenarioRow.catalogue_id == catalogue_id))
    total = int(session.scalar(select(func.count()).select_from(base.subquery())) or 0)
    if order_by == "index":
        order: list[Any] = [ScenarioRow.idx.desc() if desc else ScenarioRow.idx]
    else:
        col = _column(order_by)
        order = [col.is_(None), col.desc() if desc else col.asc(), ScenarioRow.idx]
    rows = list(session.scalars(base.order_by(*order).offset(offset).limit(limit)))
    return total, rows


def class_counts(session: Session, catalogue_id: str) -> dict[str, int]:
    """How many scenarios of each criticality class a catalogue has: every class, zeros
    included, in the classes' order (``unscored``: not scored, only when there are any)."""
    from riskcore.criticality import CLASSES

    stmt = (select(ScenarioRow.class_, func.count()).where(
        ScenarioRow.catalogue_id == catalogue_id).group_by(ScenarioRow.class_))
    found = {("unscored" if k is None else str(k)): int(v) for k, v in session.execute(stmt)}
    return _with_zeros(found, CLASSES, "unscored")


def support_counts(session: Session, catalogue_id: str) -> dict[str, int]:
    """How many scenarios of each data-support class (issue 25) a catalogue has, zeros
    included (``unknown``: stored without support, only when there are any)."""
    from sampler.model import SUPPORT_CLASSES

    stmt = (select(ScenarioRow.support, func.count()).where(
        ScenarioRow.catalogue_id == catalogue_id).group_by(ScenarioRow.support))
    found = {("unknown" if k is None else str(k)): int(v) for k, v in session.execute(stmt)}
    return _with_zeros(found, SUPPORT_CLASSES, "unknown")


def _with_zeros(found: dict[str, int], names: Sequence[str], missing: str) -> dict[str, int]:
    out = {name: found.pop(name, 0) for name in names}
    out.update(sorted(found.items()))  # a class this code does not know, then "missing"
    if missing in out:
        out[missing] = out.pop(missing)
    return out


def iter_scenarios(session: Session, catalogue_id: str,
                   batch: int = 1000) -> Iterator[ScenarioRow]:
    """All scenario rows of a catalogue in index order, fetched in batches."""
    last = -1
    while True:
        rows = scenario_batch(session, catalogue_id, last, batch)
        if not rows:
            return
        yield from rows
        last = rows[-1].idx


def scenario_batch(session: Session, catalogue_id: str, after: int,
                   limit: int) -> list[ScenarioRow]:
    """Up to ``limit`` scenario rows with index > ``after``, in index order."""
    stmt = (select(ScenarioRow).where(ScenarioRow.catalogue_id == catalogue_id,
                                      ScenarioRow.idx > after)
            .order_by(ScenarioRow.idx).limit(limit))
    return list(session.scalars(stmt))


def chunk_rows(session: Session, catalogue_id: str) -> list[ChunkRow]:
    stmt = select(ChunkRow).where(ChunkRow.catalogue_id == catalogue_id).order_by(
        ChunkRow.chunk_index)
    return list(session.scalars(stmt))


#: the scenario columns whose distribution a catalogue's status reports
STAT_COLUMNS = ("risk", "ttc", "exposure_weight", "btn", "a_req", "ttr_true",
                "r157_cc_impact_speed", "none_impact_speed", "r_dep_tp", "alarm_time")


def value_statistics(values: np.ndarray) -> dict[str, Any]:
    """Count, min, max, mean, p05 … p95 of the finite values of a float array (NaN = null),
    and ``count_inf``, how many are +inf. The quantiles are exact: ``numpy.quantile``'s
    default (linear interpolation between order statistics)."""
    n_inf = int(np.count_nonzero(values == np.inf))
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return {"count": 0, "count_inf": n_inf}
    p05, p25, p50, p75, p95 = (float(v) for v in np.quantile(finite, QUANTILES))
    return {"count": int(finite.size), "count_inf": n_inf, "min": float(finite.min()),
            "max": float(finite.max()), "mean": float(finite.mean()), "p05": p05,
            "p25": p25, "p50": p50, "p75": p75, "p95": p95}


#: the quantiles of ``value_statistics``
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)


def _stat_row_value(row: dict[str, Any], name: str) -> float:
    v = row.get("class_" if name == "class" else name)
    return math.nan if v is None else float(v)


def _stat_blob(rows: Sequence[dict[str, Any]]) -> bytes:
    """The ``stat_values`` of a chunk's rows (as stored) in .npy form."""
    values = np.array([[_stat_row_value(r, n) for n in STAT_COLUMNS] for r in rows],
                      dtype=np.float64).reshape(len(rows), len(STAT_COLUMNS))
    buf = io.BytesIO()
    np.save(buf, values, allow_pickle=False)
    return buf.getvalue()


def stat_values(session: Session, catalogue_id: str,
                chunks: Collection[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(chunk_index, values)`` of a catalogue's rows (of ``chunks``; None: all):
    ``values`` has one float column per ``STAT_COLUMNS`` name (NaN = null).

    Each chunk row keeps its values as one blob (``store_chunk``); chunks stored before
    that (or with other columns) are read from their scenario rows: one query, plain tuples
    (Core rows, no ORM objects), turned into arrays by ``numpy.fromiter`` (``numpy.array``
    of a list of tuples is ~30x slower).
    """
    stmt = select(ChunkRow.chunk_index, ChunkRow.stat_columns, ChunkRow.stat_values).where(
        ChunkRow.catalogue_id == catalogue_id)
    if chunks is not None:
        stmt = stmt.where(ChunkRow.chunk_index.in_(sorted(chunks)))
    index_parts: list[np.ndarray] = []
    value_parts: list[np.ndarray] = []
    scan: list[int] = []
    for index, names, blob in session.connection().execute(stmt).all():
        if blob is None or names != list(STAT_COLUMNS):
            scan.append(int(index))
            continue
        values = np.load(io.BytesIO(blob), allow_pickle=False)
        index_parts.append(np.full(values.shape[0], int(index), dtype=np.int64))
        value_parts.append(values)
    if scan:
        chunk_of, values = _scan_stat_values(session, catalogue_id, scan)
        index_parts.append(chunk_of)
        value_parts.append(values)
    if not value_parts:
        return np.zeros(0, dtype=np.int64), np.zeros((0, len(STAT_COLUMNS)))
    return np.concatenate(index_parts), np.concatenate(value_parts)


def _scan_stat_values(session: Session, catalogue_id: str,
                      chunks: Collection[int]) -> tuple[np.ndarray, np.ndarray]:
    """``stat_values`` of the given chunks from their scenario rows."""
    columns = [ScenarioRow.chunk_index, *(getattr(ScenarioRow, n) for n in STAT_COLUMNS)]
    stmt = select(*columns).where(ScenarioRow.catalogue_id == catalogue_id,
                                  ScenarioRow.chunk_index.in_(sorted(chunks)))
    rows = session.connection().execute(stmt).all()
    width = len(columns)
    flat = np.fromiter((math.nan if v is None else v for row in rows for v in row),
                       dtype=np.float64, count=len(rows) * width).reshape(len(rows), width)
    return flat[:, 0].astype(np.int64), flat[:, 1:]


def statistics_of(values: np.ndarray) -> dict[str, Any]:
    """``value_statistics`` of each column of ``stat_values``' array, by STAT_COLUMNS name."""
    return {name: value_statistics(values[:, j]) for j, name in enumerate(STAT_COLUMNS)}


def summary_statistics(session: Session, catalogue_id: str) -> dict[str, Any]:
    """Distribution summaries (finite values; ``count_inf``: how many are +inf) of the
    ``STAT_COLUMNS``: risk, TTC, exposure weight and the criticality margins.

    One scan of the catalogue's rows (``stat_values``), summarised by numpy: not a sort
    per quantile and column in SQL. ``app.catalogues.describe`` keeps the values per chunk
    and reads only the chunks stored since its last poll.
    """
    return statistics_of(stat_values(session, catalogue_id)[1])


def delete_catalogue(session: Session, catalogue_id: str) -> None:
    row = get_catalogue(session, catalogue_id)
    session.execute(delete(ScenarioRow).where(ScenarioRow.catalogue_id == catalogue_id))
    session.execute(delete(ChunkRow).where(ChunkRow.catalogue_id == catalogue_id))
    session.delete(row)
    session.flush()


def remove_catalogue_files(data_dir: Path, catalogue_id: str) -> None:
    """Remove a deleted catalogue's chunk files (call after the deletion committed)."""
    shutil.rmtree(data_dir / "catalogues" / catalogue_id, ignore_errors=True)


def scenario_columns(session: Session, catalogue_id: str,
                     batch: int = 5000) -> Iterator[tuple[int, Any, Any, Any, Any]]:
    """``(idx, params, risk, ttc, summary)`` of every scenario of a catalogue in index order,
    as plain tuples fetched in batches (no ORM objects: the dashboard's bulk read)."""
    last = -1
    while True:
        stmt = (select(ScenarioRow.idx, ScenarioRow.params, ScenarioRow.risk, ScenarioRow.ttc,
                       ScenarioRow.summary)
                .where(ScenarioRow.catalogue_id == catalogue_id, ScenarioRow.idx > last)
                .order_by(ScenarioRow.idx).limit(batch))
        rows = session.execute(stmt).all()
        if not rows:
            return
        for row in rows:
            yield (int(row[0]), row[1], row[2], row[3], row[4])
        last = int(rows[-1][0])
