"""Catalogue use cases shared by the HTTP routes and the CLI: create, run, describe, list,
page, export and delete. Routes and CLI commands stay thin wrappers around these."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app import budget, domain, jsonconv
from app.context import ServiceContext
from app.db import chunkfile
from app.db import repository as repo
from app.db.models import CatalogueRow, ScenarioRow, utcnow
from app.errors import Conflict, InvalidInput, NotFound, ServiceError
from app.jobs.chunk import CatalogueSpec, rebuild_scenario
from app.jobs.runner import scenarios_done
from app.limits import check_constraints
from app.rates import RegionRates, catalogue_rates
from app.schemas import PRegion
from app.services.filters import parse_filters
from app.statuses import CatalogueStage, CatalogueStatus, ChunkProgress
from riskcore import ConcreteScenario
from sampler import SAMPLER_NAMES
from sampler.scenario import SCORE_FIELDS, ScenarioRecord


def check_n(ctx: ServiceContext, n: int) -> None:
    """A catalogue's size within ``catalogue_n_limit`` (422 naming ``body.n``): checked
    before the client's quota, so an oversized request is the client's error, not a 429."""
    limit = ctx.settings.catalogue_n_limit
    if not 1 <= n <= limit:
        raise InvalidInput(f"n must be between 1 and {limit}, got {n}", field="body.n")


#: samplers that need a region smaller than the whole model
SUBSET_METHODS = ("subset", "subset-is")


@dataclass(frozen=True)
class ValidCatalogue:
    """A catalogue request that passed :func:`validate`, ready to be stored."""
    model_id: str
    n: int
    seed: int
    chunk_size: int
    spec: dict[str, Any]


def create(ctx: ServiceContext, *, n: int, seed: int, constraints: list[str],
           model: str | None = None, method: str = "auto", score: bool = True,
           chunk_size: int | None = None, wagner_scan: bool = False) -> CatalogueRow:
    """Validate and store a new catalogue job (status ``queued``); the caller runs it."""
    return store(ctx, validate(ctx, n=n, seed=seed, constraints=constraints, model=model,
                               method=method, score=score, chunk_size=chunk_size,
                               wagner_scan=wagner_scan))


def validate(ctx: ServiceContext, *, n: int, seed: int, constraints: list[str],
             model: str | None = None, method: str = "auto", score: bool = True,
             chunk_size: int | None = None, wagner_scan: bool = False) -> ValidCatalogue:
    """Every check of a catalogue request (422 or 404 naming the field), nothing stored:
    the route checks it before it takes the client's quota."""
    check_n(ctx, n)
    if method not in SAMPLER_NAMES:
        raise InvalidInput(f"unknown sampler {method!r}; choose one of "
                           f"{', '.join(SAMPLER_NAMES)}", field="body.sampler")
    if method in SUBSET_METHODS and not constraints:  # as POST /scenarios refuses it
        raise InvalidInput(f"sampler {method!r}: subset simulation needs at least one "
                           "constraint (without one the region is the whole model); give "
                           "constraints, or use auto, rejection or mcmc",
                           field="body.constraints")
    size = chunk_size or ctx.settings.chunk_size
    if size < 1:
        raise InvalidInput("chunk_size must be at least 1", field="body.chunk_size")
    model_id = ctx.resolve_model_id(model)
    fitted = ctx.model(model_id)  # 404 for an unknown model, before anything is stored
    check_constraints(constraints, ctx.settings)
    parsed = domain.parse_constraints(constraints)
    # 422 for an empty region now rather than a job that fails (a P(A) estimate: < 1 s)
    budget.precheck(lambda: domain.estimate_region(fitted, parsed, seed))
    spec = {"constraints": list(constraints), "method": method, "score": bool(score),
            "wagner_scan": bool(score and wagner_scan),
            "store_trajectories": bool(ctx.settings.store_trajectories)}
    return ValidCatalogue(model_id=model_id, n=int(n), seed=int(seed), chunk_size=size,
                          spec=spec)


def store(ctx: ServiceContext, valid: ValidCatalogue) -> CatalogueRow:
    """Store a validated catalogue job (status ``queued``)."""
    n, size = valid.n, valid.chunk_size
    with ctx.db.session() as s:
        row = CatalogueRow(id=repo.new_id("cat"), model_id=valid.model_id, status="queued",
                           n=n, seed=valid.seed, chunk_size=size,
                           n_chunks=(n + size - 1) // size, spec=dict(valid.spec))
        s.add(row)
    return row


class _ChunkValues:
    """A catalogue's ``repo.stat_values`` kept per stored chunk (chunks never change once
    stored), so a status poll reads only the chunks stored since the last one."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.parts: dict[int, np.ndarray] = {}


def _stat_values(ctx: ServiceContext, session: Session, catalogue_id: str) -> np.ndarray:
    """The catalogue's status values (rows x ``repo.STAT_COLUMNS``) of every stored chunk,
    in chunk order; the chunks seen before come from ``ctx``'s cache."""
    kept: _ChunkValues = ctx.cache("catalogue.stat_values", 8).get((catalogue_id,),
                                                                   _ChunkValues)
    with kept.lock:
        stored = repo.stored_chunk_indices(session, catalogue_id)
        new = stored - kept.parts.keys()
        if new:
            chunk_of, values = repo.stat_values(session, catalogue_id,
                                                None if not kept.parts else new)
            order = np.argsort(chunk_of, kind="stable")
            for rows in np.split(order, np.flatnonzero(np.diff(chunk_of[order])) + 1):
                c = int(chunk_of[rows[0]]) if rows.size else -1
                if c in new:
                    kept.parts[c] = values[rows]
            for c in new - kept.parts.keys():  # a chunk without rows
                kept.parts[c] = values[:0]
        parts = [kept.parts[c] for c in sorted(stored)]
    if not parts:
        return np.zeros((0, len(repo.STAT_COLUMNS)))
    return np.concatenate(parts)


def run(ctx: ServiceContext, catalogue_id: str, *,
        progress: Callable[[int, int], None] | None = None,
        note: Callable[[str], None] | None = None,
        stage: Callable[[str, int, int], None] | None = None) -> str:
    """Run (or resume) a catalogue's job in this process until it ends; its final status.
    ``progress(done, total)`` per scenario, ``note(text)`` for messages, ``stage(name,
    done, total)`` for the P(A) estimate's stages (``CatalogueRunner.run``)."""
    return ctx.runner().run(catalogue_id, progress=progress, note=note, stage=stage)


def mark_cancelled(ctx: ServiceContext, catalogue_id: str) -> tuple[int, int]:
    """Record that the job running in this process was stopped by its user (the CLI's
    Ctrl-C): status ``cancelled`` unless it ended meanwhile; its chunks stay stored and
    ``run`` resumes it. Returns (scenarios stored, n)."""
    with ctx.db.session() as s:
        row = repo.get_catalogue(s, catalogue_id)
        if row.status in repo.ACTIVE:
            row.status = "cancelled"
            row.updated_at = utcnow()
        stored = repo.count_scenarios(s, catalogue_id)
        return stored, int(row.n)


def get_catalogue(ctx: ServiceContext, catalogue_id: str) -> CatalogueRow:
    """A stored catalogue (404 for an unknown id)."""
    with ctx.db.read_session() as s:
        return repo.get_catalogue(s, catalogue_id)


def list_catalogues(ctx: ServiceContext) -> list[CatalogueRow]:
    """Every catalogue, oldest first."""
    with ctx.db.read_session() as s:
        return list(repo.list_catalogues(s))


@dataclass(frozen=True)
class ScenarioPage:
    """One page of a catalogue's stored scenarios: the records and how many match."""

    total: int
    records: list[ScenarioRecord]


def page_scenarios(ctx: ServiceContext, catalogue_id: str, flt: repo.ScenarioFilter,
                   offset: int, limit: int, *, order_by: str, desc: bool) -> ScenarioPage:
    """Scenarios of a catalogue ranked by ``order_by`` and filtered (``page_filter``);
    404 for an unknown catalogue."""
    with ctx.db.read_session() as s:
        repo.get_catalogue(s, catalogue_id)  # 404 for an unknown catalogue
        total, rows = repo.page_scenarios(s, catalogue_id, flt, offset, limit,
                                          order_by=order_by, desc=desc)
        return ScenarioPage(total=total, records=[record_of(r) for r in rows])


def describe(ctx: ServiceContext, catalogue_id: str) -> CatalogueStatus:
    """Status, progress, counts, P(A) and summary statistics of a catalogue."""
    with ctx.db.read_session() as s:
        row = repo.get_catalogue(s, catalogue_id)
        n_done, stored = repo.chunk_counts(s, catalogue_id)
        chunks = (repo.stored_chunk_indices(s, catalogue_id)
                  if row.status == "running" else set())
    # per scenario: the workers' reports of the chunks being computed (app.db.chunkfile)
    folder = chunkfile.progress_dir(ctx.data_dir, catalogue_id)
    running = row.status == "running"
    done = scenarios_done(row.n, row.chunk_size, chunks, folder) if running else stored
    # the statistics change only when a chunk is stored: computed once per stored state
    key = (catalogue_id, n_done, stored, row.updated_at.isoformat())

    def compute() -> _Statistics:
        with ctx.db.read_session() as s:
            return _Statistics(summary=repo.statistics_of(_stat_values(ctx, s, catalogue_id)),
                               classes=repo.class_counts(s, catalogue_id),
                               support=repo.support_counts(s, catalogue_id))

    stats: _Statistics = ctx.cache("catalogue.statistics", 256).get(key, compute)
    stage = chunkfile.read_stage(folder) if running else None
    rates = catalogue_rates(row.p_region, stats.summary.get("exposure_weight"))
    return CatalogueStatus(
        id=row.id,
        status=row.status,
        model=row.model_id,
        n=row.n,
        seed=row.seed,
        constraints=row.spec.get("constraints", []),
        sampler=row.spec.get("method", "auto"),
        score=row.spec.get("score", True),
        wagner_scan=bool(row.spec.get("wagner_scan", False)),
        chunk_size=row.chunk_size,
        chunks=ChunkProgress(total=row.n_chunks, done=n_done),
        scenarios_stored=stored,
        scenarios_done=done,
        progress=min(1.0, done / row.n) if row.n else 1.0,
        # what the running job is doing now (the P(A) estimate can take a minute at 0 %)
        stage=None if stage is None else CatalogueStage.model_validate(stage),
        p_region=None if row.p_region is None else PRegion.model_validate(row.p_region),
        # issue 12: rates per hour / 10^6 km with both intervals, and the weights' sum
        rates=None if rates is None else RegionRates.model_validate(rates),
        summary=stats.summary,
        classes=stats.classes,
        # issue 25: how many scenarios the data support (inside / near / extrapolated)
        support=stats.support,
        error=row.error,
        created_at=row.created_at.isoformat(),
        updated_at=row.updated_at.isoformat(),
        finished_at=row.finished_at.isoformat() if row.finished_at else None,
    )


@dataclass(frozen=True)
class _Statistics:
    """A catalogue's statistics at one stored state (cached by ``describe``)."""

    summary: dict[str, dict[str, float]]
    classes: dict[str, int]
    support: dict[str, int]


def page_filter(items: Sequence[tuple[str, str]], classes: Sequence[str] = (),
                where: str = "query") -> repo.ScenarioFilter:
    """A scenario page's filters from ``name=value`` pairs (API query, CLI ``--filter``):
    ``<field>_min`` / ``<field>_max`` for the numeric fields (``repo.RANGE_FIELDS``),
    ``<field>=true|false`` for the yes/no fields, ``support=inside|near|extrapolated``
    (repeatable), and the classes. Anything else is an
    ``InvalidInput`` naming it (``where.name``)."""
    from riskcore.criticality import CLASSES
    from sampler.model import SUPPORT_CLASSES

    supports = [raw for key, raw in items if key == "support"]
    bad_support = [v for v in supports if v not in SUPPORT_CLASSES]
    if bad_support:
        raise InvalidInput(f"support: unknown data-support class {bad_support[0]!r}; valid: "
                           f"{', '.join(SUPPORT_CLASSES)}", field=f"{where}.support")
    parsed = parse_filters([(k, v) for k, v in items if k != "support"], repo.RANGE_FIELDS,
                           repo.FLAG_FIELDS, "class, support", where)
    bad = [c for c in classes if c not in CLASSES]
    if bad:
        raise InvalidInput(f"class: unknown class {bad[0]!r}; valid: {', '.join(CLASSES)}",
                           field=f"{where}.class")
    return repo.ScenarioFilter(ranges=parsed.ranges, flags=parsed.flags, classes=tuple(classes),
                               supports=tuple(supports))


def check_order(order_by: str, desc: bool | None, where: str = "query") -> bool:
    """Validate ``order_by``; the direction (default: descending except for ``index``)."""
    if order_by not in repo.ORDER_FIELDS:
        raise InvalidInput(f"order_by: unknown field {order_by!r}; valid: "
                           f"{', '.join(repo.ORDER_FIELDS)}", field=f"{where}.order_by")
    return (order_by != "index") if desc is None else bool(desc)


def record_of(row: ScenarioRow) -> ScenarioRecord:
    """The stored scenario as the service's one scored-record schema (from its columns)."""
    scores = {k: getattr(row, "class_" if k == "class" else k) for k in SCORE_FIELDS}
    return ScenarioRecord.model_validate({
        "index": row.idx, "params": row.params, "ttc": math.inf if row.ttc is None else row.ttc,
        "exposure_weight": row.exposure_weight, "error": row.error, **scores,
        **support_of(row)})


def support_of(row: ScenarioRow) -> dict[str, Any]:
    """The stored scenario's data-support fields (``SUPPORT_FIELDS``; all null when it was
    stored before issue 25 or its model has no training rows)."""
    out: dict[str, Any] = {"support": row.support, "support_distance": row.support_distance,
                           "support_excess": row.support_excess}
    out.update(jsonconv.decode(row.support_detail or {}))
    return out


def export_summary(row: ScenarioRow) -> dict[str, Any]:
    """The flat summary an export gets for one scenario (scores + exposure weight)."""
    summary: dict[str, Any] = dict(jsonconv.decode(row.summary or {}))
    summary["scenario_id"] = row.idx
    summary["exposure_weight"] = row.exposure_weight
    summary["support"] = row.support
    summary["support_distance"] = row.support_distance
    summary["support_excess"] = row.support_excess
    summary["error"] = row.error
    return summary


def _spec_of(cat: CatalogueRow) -> CatalogueSpec:
    """The catalogue's spec without the model (enough to rebuild its scenarios)."""
    return CatalogueSpec(n=cat.n, seed=cat.seed, chunk_size=cat.chunk_size, model_json="",
                         constraints=tuple(cat.spec.get("constraints", ())),
                         method=cat.spec.get("method", "auto"))


def stored_scenario(ctx: ServiceContext, cat: CatalogueRow,
                    row: ScenarioRow) -> tuple[ConcreteScenario | None, str]:
    """A catalogue scenario and where it came from: its chunk file when kept, else rebuilt
    exactly as the chunk built it (deterministic). None when the builder refused it."""
    with ctx.db.read_session() as s:
        chunks = {c.chunk_index: c for c in repo.chunk_rows(s, cat.id)}
    chunk = chunks.get(row.chunk_index)
    if chunk is not None and chunk.file_path is not None:
        path = ctx.data_dir / chunk.file_path
        if path.exists():
            data = chunkfile.read_at(path, row.idx - row.chunk_index * cat.chunk_size)
            return (None if data is None else ConcreteScenario.from_dict(data),
                    "stored trajectories")
    lane_width = domain.model_lane_width(ctx.model(cat.model_id))
    return (rebuild_scenario(_spec_of(cat), row.idx, row.params, lane_width),
            "rebuilt from the stored parameters")


def iter_items(ctx: ServiceContext,
               catalogue_id: str) -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
    """(scenario, summary) pairs of a finished catalogue in index order; scenarios the
    builder refused (rows with an error) have nothing to export and are left out."""
    with ctx.db.read_session() as s:
        chunks = {c.chunk_index: c for c in repo.chunk_rows(s, catalogue_id)}
        cat = repo.get_catalogue(s, catalogue_id)
        spec = _spec_of(cat)
        model_id = cat.model_id
        expected = cat.n
    lane_width: float | None = None
    current: int | None = None
    stream: Iterator[dict[str, Any] | None] | None = None
    last = -1
    seen = 0
    while True:
        # one short transaction per batch: never hold the database during a long export
        with ctx.db.read_session() as s:
            rows = repo.scenario_batch(s, catalogue_id, last, 500)
        if not rows:
            if seen != expected:  # rows gone under the export: deleted meanwhile
                raise ExportInterrupted(f"catalogue {catalogue_id}: {seen} of {expected} "
                                        "scenarios read")
            return
        last = rows[-1].idx
        seen += len(rows)
        for row in rows:
            if row.chunk_index != current:
                current = row.chunk_index
                chunk = chunks.get(current)
                stream = (None if chunk is None or chunk.file_path is None
                          else chunkfile.read_scenarios(ctx.data_dir / chunk.file_path))
            scenario: ConcreteScenario | None
            if stream is not None:
                data = next(stream)
                scenario = None if data is None else ConcreteScenario.from_dict(data)
            else:  # trajectories not stored: rebuild them (deterministic)
                if lane_width is None:
                    lane_width = domain.model_lane_width(ctx.model(model_id))
                scenario = rebuild_scenario(spec, row.idx, row.params, lane_width)
            if scenario is not None:
                yield scenario, export_summary(row)


def manifest(ctx: ServiceContext, catalogue_id: str) -> dict[str, Any]:
    from app.exports import build_manifest

    with ctx.db.session() as s:
        row = repo.get_catalogue(s, catalogue_id)
        model = repo.get_model(s, row.model_id, field="model")
    p = jsonconv.decode(row.p_region) if row.p_region else None
    return build_manifest(
        seed=row.seed, model_hash=model.model_hash,
        sampler_settings={"method": row.spec.get("method", "auto"),
                          "chunk_size": row.chunk_size,
                          "score": bool(row.spec.get("score", True))},
        constraints=list(row.spec.get("constraints", [])), p_region=p,
        extra={"n": row.n, "model_id": row.model_id},
    )


def export(ctx: ServiceContext, catalogue_id: str, fmt: str, out: Path,
           mode: str | None = None,
           progress: Callable[[int, int], None] | None = None) -> Path:
    """Write a finished catalogue to ``out`` in ``fmt`` (``app.exports``); ``mode``
    (``test``/``replay``) only for ``xosc``; ``progress(done, n)`` hears each scenario
    written (``scengen catalogue export``'s bar: 13 s without a sign before)."""
    from app.exports import EXPORT_FORMATS, ExportError, export_catalogue

    if fmt not in EXPORT_FORMATS:
        raise InvalidInput(f"unknown format {fmt!r}; choose one of {', '.join(EXPORT_FORMATS)}",
                           field="query.format")
    if mode is not None and fmt != "xosc":
        raise InvalidInput(f"mode {mode!r}: only the xosc export has modes, not {fmt!r}",
                           field="query.mode")
    with ctx.db.session() as s:
        row = repo.get_catalogue(s, catalogue_id)
        if row.status != "done":
            raise Conflict(f"catalogue {catalogue_id} is {row.status}; export needs a "
                           "finished catalogue", field="path.catalogue_id")
        n = row.n
    items: Iterable[Any] = iter_items(ctx, catalogue_id)
    if progress is not None:
        items = _counted(items, n, progress)
    try:
        return export_catalogue(fmt, items, manifest(ctx, catalogue_id), out, mode=mode)
    except Exception as exc:
        # A done catalogue's rows and files never change, so what was read is a consistent
        # snapshot unless the catalogue was deleted while it was read (a chunk file or the
        # rows gone): then the export is refused whole, never truncated nor a 500.
        if not _exists(ctx, catalogue_id):
            raise NotFound(f"catalogue {catalogue_id} was deleted while it was being "
                           "exported", field="path.catalogue_id") from None
        if isinstance(exc, ExportError):
            raise ServiceError(f"export of catalogue {catalogue_id} failed: {exc}") from None
        raise


def _counted(items: Iterable[Any], n: int,
             progress: Callable[[int, int], None]) -> Iterator[Any]:
    """``items`` unchanged, with ``progress(done, n)`` after each (and once at 0)."""
    progress(0, n)
    for done, item in enumerate(items, 1):
        yield item
        progress(done, n)


class ExportInterrupted(RuntimeError):
    """The rows of a catalogue being exported went away (it was deleted meanwhile)."""


def _exists(ctx: ServiceContext, catalogue_id: str) -> bool:
    with ctx.db.read_session() as s:
        return s.get(CatalogueRow, catalogue_id) is not None


def delete(ctx: ServiceContext, catalogue_id: str) -> None:
    with ctx.db.session() as s:
        repo.delete_catalogue(s, catalogue_id)
    repo.remove_catalogue_files(ctx.data_dir, catalogue_id)
