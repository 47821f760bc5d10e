"""Evaluations (issue 24): a system under test driven through importance-sampled cut-ins,
its collision probability per cut-in and its rate per hour (``sampler.campaign.evaluate``).

Use cases shared by ``POST /evaluations`` and friends and ``scengen evaluate``:

- ``create`` validates a request and stores a queued job; ``run_job`` runs (or resumes) it:
  every chunk the campaign finishes is stored at once, with its simulated runs, in one
  transaction (``EvaluationChunkRow`` holds ``ChunkResult.to_dict()``); a job that was
  interrupted (crash, shutdown) replays its stored chunks through
  ``evaluate(..., stored=...)`` instead of simulating them again, so the result is the
  same as an uninterrupted run. Cancel: ``JobManager.cancel`` (``DELETE``).
- ``describe``, ``page_runs``, ``export`` (the failing runs, rebuilt from their parameter
  vectors with the scenario builder), ``delete``.
- ``campaign`` runs a campaign in this process without the store (the CLI).

The runner that simulates the SUT is ``sampler.campaign.sut_runner`` unless the context
carries another (``ServiceContext.campaign_runner``: tests inject a stand-in there).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, SupportsFloat

import numpy as np
from sqlalchemy import delete as sql_delete
from sqlalchemy import func, insert, select
from sqlalchemy.exc import IntegrityError

from app import budget, domain, jsonconv
from app.context import ServiceContext
from app.db import repository as repo
from app.db.models import EvaluationChunkRow, EvaluationRow, EvaluationRunRow, utcnow
from app.errors import Conflict, InvalidInput, NotFound, ServiceError
from app.jobs.fair import FairExecutor, InlineFutures, JobCancelled, Share
from app.limits import check_constraints
from app.services import suts
from app.services.filters import parse_filters
from app.statuses import EvaluationStatus
from datasets import PARAM_NAMES
from riskcore import ConcreteScenario

# the stop rule's default rhw: defined and explained in sampler.campaign.evaluate, kept
# here under its name for the routes and the tests (the CLI writes it out: app.cli.evaluate)
from sampler.campaign import DEFAULT_RHW as DEFAULT_RHW
from sampler.campaign import DEFAULT_ROULETTE, ROULETTE_FINAL_ALPHA
from sampler.campaign import MAX_ROULETTE as MAX_ROULETTE

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from sampler import CutInGMM
    from sampler.campaign import CampaignResult, ChunkResult, Runner

log = logging.getLogger("scengen.jobs")

#: runs per chunk when a request does not say
DEFAULT_BATCH = 2000
#: the most runs a campaign with the stop rule may use when a request does not say
DEFAULT_MAX_RUNS = 200_000
#: columns /runs may order by; filters: <name>_min/_max on the numbers, flags =true|false
ORDER_FIELDS = ("run", "impact_speed", "r_dep_peak", "min_gap", "min_ttc", "weight")
RANGE_FIELDS = ("impact_speed", "r_dep_peak", "min_gap", "min_ttc")
FLAG_FIELDS = ("collided", "must_avoid", "violation")
VS_CAREFUL = ("worse", "same", "better")
#: export formats of the failing runs
EXPORT_FORMATS = ("json", "xosc", "commonroad")

ProgressFn = Callable[[str, int, int], None]
#: (sut factory, simulator settings dict or None) -> a ``sampler.campaign.Runner``
RunnerMaker = Callable[["suts.SutFactory", "dict[str, Any] | None"], "Runner"]


class Cancelled(Exception):
    """Raised inside the campaign's callbacks to stop it (cancel or shutdown)."""


def _campaign_face() -> Any:
    import importlib

    return importlib.import_module("sampler.campaign")


def default_runner(factory: suts.SutFactory, settings: dict[str, Any] | None,
                   risk: bool = False) -> Runner:
    """``sampler.campaign.sut_runner`` with the careful driver beside the SUT (for
    ``vs_careful``); ``settings`` are ``riskcore.sut.SimSettings`` fields; ``risk``: Wagner's
    r_dep / r_ind of the SUT's drive per run."""
    import importlib

    sim = None
    if settings:
        rs = importlib.import_module("riskcore.sut")
        try:
            sim = rs.SimSettings.from_dict(dict(settings))
        except (TypeError, ValueError, KeyError) as exc:
            raise InvalidInput(f"settings: {exc}", field="body.settings") from None
    face = _campaign_face()
    if not hasattr(face, "sut_runner"):
        raise ServiceError("evaluations need sampler.campaign.sut_runner, which this "
                           "version does not have yet")
    runner: Runner = face.sut_runner(factory, settings=sim, careful=True, name=factory.name,
                                     risk=risk)
    return runner


def runner_for(ctx: ServiceContext | None, factory: suts.SutFactory,
               settings: dict[str, Any] | None, risk: bool = False) -> Runner:
    maker: RunnerMaker | None = getattr(ctx, "campaign_runner", None) if ctx else None
    if maker is not None:  # a runner injected by the caller (tests): it knows its fields
        return maker(factory, settings)
    return default_runner(factory, settings, risk) if risk else default_runner(factory, settings)


def check_settings(settings: Mapping[str, Any] | None, field: str) -> None:
    """Simulator settings as ``riskcore.sut.SimSettings`` takes them (``InvalidInput``
    naming ``field`` otherwise)."""
    if not settings:
        return
    import importlib

    rs = importlib.import_module("riskcore.sut")
    try:
        rs.SimSettings.from_dict(dict(settings))
    except (TypeError, ValueError, KeyError) as exc:
        raise InvalidInput(f"{field.removeprefix('body.')}: {exc}", field=field) from None


# --------------------------------------------------------------------------- create
#: the campaign's adaptation stages (``sampler.campaign.evaluate(adapt=...)``), default first
ADAPT = ("ce", "kernels")


@dataclass(frozen=True)
class CampaignSpec:
    """What a campaign is: everything ``evaluate`` needs besides the model and runner."""

    sut: str
    sut_params: dict[str, Any]
    constraints: list[str]
    n: int | None
    rhw: float
    max_runs: int
    seed: int
    batch_size: int
    settings: dict[str, Any] | None
    risk: bool = False  # r_dep / r_ind of the SUT's drive per run (costly)
    #: how later chunks adapt their proposal (``sampler.campaign.evaluate``): "ce"
    #: (cross-entropy, the default) or "kernels"; a stored spec without it was a kernels
    #: campaign (``from_dict``)
    adapt: str = "ce"
    #: the final stage's band step (``sampler.campaign.evaluate(band_step=...)``): off by
    #: default, and a stored spec without it ran without it (``from_dict``)
    band_step: bool = False
    #: weight roulette's factor (``sampler.campaign.evaluate(roulette=...)``; 0: off): a
    #: new request's default is ``DEFAULT_ROULETTE`` with adapt "ce", and a stored spec
    #: without it ran without it (``from_dict``)
    roulette: float = 0.0
    #: the model's defensive share in the final stage
    #: (``sampler.campaign.evaluate(final_alpha=...)``; None: the pilot's 0.15): a new
    #: request with the roulette on runs ``ROULETTE_FINAL_ALPHA``, and a stored spec
    #: without it ran with None (``from_dict``)
    final_alpha: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"sut": self.sut, "sut_params": self.sut_params,
                "constraints": self.constraints, "n": self.n, "rhw": self.rhw,
                "max_runs": self.max_runs, "seed": self.seed,
                "batch_size": self.batch_size, "settings": self.settings,
                "risk": self.risk, "adapt": self.adapt, "band_step": self.band_step,
                **({"roulette": self.roulette} if self.roulette else {}),
                **({"final_alpha": self.final_alpha} if self.final_alpha is not None
                   else {})}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CampaignSpec:
        return cls(sut=str(d["sut"]), sut_params=dict(d.get("sut_params") or {}),
                   constraints=list(d.get("constraints") or []), n=d.get("n"),
                   rhw=float(d.get("rhw", 0.3)), max_runs=int(d["max_runs"]),
                   seed=int(d.get("seed", 0)), batch_size=int(d["batch_size"]),
                   settings=d.get("settings"), risk=bool(d.get("risk", False)),
                   adapt=str(d.get("adapt") or "kernels"),
                   band_step=bool(d.get("band_step", False)),
                   roulette=float(d.get("roulette", 0.0)),
                   final_alpha=None if d.get("final_alpha") is None
                   else float(d["final_alpha"]))

    @property
    def planned(self) -> int:
        return int(self.n) if self.n is not None else int(self.max_runs)


def default_roulette(adapt: str, roulette: float | None) -> float:
    """The weight roulette's factor a new campaign runs with: as given, else
    ``DEFAULT_ROULETTE`` with adapt "ce" and 0 (off) with "kernels"."""
    if roulette is not None:
        return float(roulette)
    return DEFAULT_ROULETTE if adapt == "ce" else 0.0


def default_final_alpha(roulette: float) -> float | None:
    """The model's final-stage share a new campaign runs with: ``ROULETTE_FINAL_ALPHA``
    with the weight roulette on (its runs are the ones the roulette cannot leave out),
    None (the pilot's share) without."""
    return ROULETTE_FINAL_ALPHA if roulette > 0 else None


def check_spec(spec: CampaignSpec, limit: int, where: str = "body") -> None:
    """Range checks of a campaign's numbers (``InvalidInput`` naming the field: ``body.n``
    for a request; ``--n`` for the CLI, ``where=""``)."""
    def f(name: str) -> str:
        return f"{where}.{name}" if where else "--" + name.replace("_", "-")

    if spec.n is not None and not 1 <= spec.n <= limit:
        raise InvalidInput(f"{f('n')}: must be between 1 and {limit} runs, got {spec.n}",
                           field=f("n"))
    if not 1 <= spec.max_runs <= limit:
        raise InvalidInput(f"{f('max_runs')}: must be between 1 and {limit} runs, got "
                           f"{spec.max_runs}", field=f("max_runs"))
    if not (math.isfinite(spec.rhw) and 0 < spec.rhw < 10):
        raise InvalidInput(f"{f('rhw')}: the stop rule's relative half-width must be in "
                           f"(0, 10), got {spec.rhw}", field=f("rhw"))
    if not 1 <= spec.batch_size <= 100_000:
        raise InvalidInput(f"{f('batch_size')}: must be between 1 and 100000, got "
                           f"{spec.batch_size}", field=f("batch_size"))
    if isinstance(spec.seed, bool) or spec.seed < 0:
        raise InvalidInput(f"{f('seed')}: must be an integer >= 0, got {spec.seed}",
                           field=f("seed"))
    if spec.adapt not in ADAPT:
        raise InvalidInput(f"{f('adapt')}: must be one of {', '.join(ADAPT)}, got "
                           f"{spec.adapt!r}", field=f("adapt"))
    if spec.band_step and spec.adapt != "ce":
        raise InvalidInput(f"{f('band_step')}: the band step is a stage of adapt 'ce', got "
                           f"adapt {spec.adapt!r}", field=f("band_step"))
    if not (math.isfinite(spec.roulette) and 0 <= spec.roulette <= MAX_ROULETTE):
        raise InvalidInput(f"{f('roulette')}: the weight roulette's factor must be in "
                           f"[0, {MAX_ROULETTE:g}] (0: off), got {spec.roulette}",
                           field=f("roulette"))
    if spec.roulette and spec.adapt != "ce":
        raise InvalidInput(f"{f('roulette')}: weight roulette is a stage of adapt 'ce', got "
                           f"adapt {spec.adapt!r}", field=f("roulette"))


def create(ctx: ServiceContext, *, sut: str, sut_params: Mapping[str, Any] | None = None,
           model: str | None = None, constraints: Sequence[str] = (), n: int | None = None,
           rhw: float = DEFAULT_RHW, max_runs: int | None = None, seed: int = 0,
           batch_size: int | None = None,
           settings: Mapping[str, Any] | None = None, risk: bool = False,
           adapt: str = "ce", band_step: bool = False,
           roulette: float | None = None) -> EvaluationRow:
    """Validate and store a queued evaluation job; the caller submits it. ``sut`` must be a
    registered name (a request never names a module)."""
    return store(ctx, validate(ctx, sut=sut, sut_params=sut_params, model=model,
                               constraints=constraints, n=n, rhw=rhw, max_runs=max_runs,
                               seed=seed, batch_size=batch_size, settings=settings,
                               risk=risk, adapt=adapt, band_step=band_step,
                               roulette=roulette))


@dataclass(frozen=True)
class ValidEvaluation:
    """A request that passed ``validate``: what ``store`` writes."""

    model_id: str
    sut: str
    spec: CampaignSpec


def validate(ctx: ServiceContext, *, sut: str, sut_params: Mapping[str, Any] | None = None,
             model: str | None = None, constraints: Sequence[str] = (), n: int | None = None,
             rhw: float = DEFAULT_RHW, max_runs: int | None = None, seed: int = 0,
             batch_size: int | None = None, settings: Mapping[str, Any] | None = None,
             risk: bool = False, adapt: str = "ce",
             band_step: bool = False, roulette: float | None = None) -> ValidEvaluation:
    """Every check of ``create`` (``InvalidInput`` naming the field, 404 for an unknown
    model), nothing stored: the route asks for the client's quota only after it, so that a
    bad request is told what is wrong (422), not to wait (429)."""
    entry = suts.resolve(sut, allow_import=False, field="body.sut")
    roulette_k = default_roulette(adapt, roulette)
    spec = CampaignSpec(sut=entry.name, sut_params=dict(sut_params or {}),
                        constraints=list(constraints), n=n, rhw=float(rhw),
                        max_runs=int(max_runs or min(DEFAULT_MAX_RUNS,
                                                     ctx.settings.catalogue_n_limit)),
                        seed=int(seed), batch_size=int(batch_size or DEFAULT_BATCH),
                        settings=dict(settings) if settings else None, risk=bool(risk),
                        adapt=str(adapt), band_step=bool(band_step),
                        roulette=roulette_k, final_alpha=default_final_alpha(roulette_k))
    check_spec(spec, ctx.settings.catalogue_n_limit)
    model_id = ctx.resolve_model_id(model)
    fitted = ctx.model(model_id)  # 404 before anything is stored
    if spec.constraints:
        check_constraints(spec.constraints, ctx.settings)
        parsed = domain.parse_constraints(spec.constraints)
        # 422 for an empty region now (a rare one is left to the job: app.budget.precheck)
        budget.precheck(lambda: domain.estimate_region(fitted, parsed, spec.seed))
    suts.make_factory(entry, spec.sut_params, field="body.sut_params")
    check_settings(spec.settings, "body.settings")
    return ValidEvaluation(model_id=model_id, sut=entry.name, spec=spec)


def store(ctx: ServiceContext, valid: ValidEvaluation) -> EvaluationRow:
    """Store a validated evaluation as a queued job (the caller submits it)."""
    spec = valid.spec
    with ctx.db.session() as s:
        row = EvaluationRow(id=repo.new_id("eval"), model_id=valid.model_id, sut=valid.sut,
                            status="queued", seed=spec.seed, spec=jsonconv.encode(
                                spec.to_dict()), runs_planned=spec.planned, runs_done=0)
        s.add(row)
    return row


# --------------------------------------------------------------------------- chunks
def encode_chunk(chunk: ChunkResult) -> bytes:
    return zlib.compress(json.dumps(chunk.to_dict(), separators=(",", ":"),
                                    allow_nan=False).encode(), 6)


def decode_chunk(data: bytes) -> ChunkResult:
    chunk: ChunkResult = _campaign_face().ChunkResult.from_dict(
        json.loads(zlib.decompress(data)))
    return chunk


def _num(v: SupportsFloat) -> float | None:
    f = float(v)
    return None if math.isnan(f) else f


def run_rows(evaluation_id: str, chunk: ChunkResult, batch_size: int) -> list[dict[str, Any]]:
    """The simulated runs of a chunk as ``evaluation_runs`` rows (``run`` counts every draw
    of the campaign: chunk k's rows start at k * batch_size)."""
    names = [str(p.get("part", "")) for p in getattr(chunk, "proposal", [])]
    out: list[dict[str, Any]] = []
    outcome: dict[str, np.ndarray] = {k: np.asarray(v) for k, v in chunk.outcome.items()}
    for i in np.flatnonzero(np.asarray(chunk.simulated, dtype=bool)).tolist():
        rec: dict[str, Any] = {"run": chunk.index * batch_size + i, "chunk": chunk.index,
                               "seed": str(int(chunk.seeds[i]))}
        rec.update({k: float(v) for k, v in zip(PARAM_NAMES, chunk.params[i].tolist(),
                                                 strict=True)})
        rec["weight_raw"] = float(chunk.weights[i])
        rec["log_p"], rec["log_q"] = float(chunk.log_p[i]), float(chunk.log_q[i])
        k = int(chunk.part[i])
        rec["part"] = names[k] if 0 <= k < len(names) else k
        for name, arr in outcome.items():
            v = arr[i]
            rec[name] = (bool(v) if arr.dtype == np.bool_ else
                         (str(v) or None) if arr.dtype.kind in "USO" else float(v))
        vs = rec.get("vs_careful")
        out.append({
            "evaluation_id": evaluation_id, "run": rec["run"], "chunk_index": chunk.index,
            "weight_raw": rec["weight_raw"], "collided": bool(rec.get("collided", False)),
            "impact_speed": _opt(rec.get("impact_speed")),
            "r_dep_peak": _opt(rec.get("r_dep_peak")), "min_gap": _opt(rec.get("min_gap")),
            "min_ttc": _opt(rec.get("min_ttc")),
            "vs_careful": vs if vs in VS_CAREFUL else None,
            "must_avoid": _flag(rec.get("must_avoid")),
            "violation": _flag(rec.get("violation")),
            "record": jsonconv.encode(rec)})
    return out


def _opt(v: Any) -> float | None:
    return None if v is None else _num(v)


def _flag(v: Any) -> bool | None:
    return None if v is None else bool(v)


def store_chunk(ctx: ServiceContext, evaluation_id: str, chunk: ChunkResult,
                batch_size: int) -> bool:
    """Store one finished chunk and its runs in one transaction; False when the evaluation
    is gone (deleted while running) or the chunk was already stored."""
    rows = run_rows(evaluation_id, chunk, batch_size)
    try:
        with ctx.db.session() as s:
            ev = s.get(EvaluationRow, evaluation_id)
            if ev is None:
                return False
            s.add(EvaluationChunkRow(evaluation_id=evaluation_id, chunk_index=chunk.index,
                                     n_runs=chunk.n, collisions=int(chunk.collided.sum()),
                                     data=encode_chunk(chunk)))
            s.flush()
            if rows:
                s.execute(insert(EvaluationRunRow), rows)
            ev.runs_done = int(ev.runs_done) + int(chunk.n)
            ev.updated_at = utcnow()
    except IntegrityError:
        return False
    return True


def stored_chunks(ctx: ServiceContext, evaluation_id: str) -> list[ChunkResult]:
    """The stored chunks in order, as ``ChunkResult``s (consecutive from 0: a gap ends the
    replay, the rest is simulated again)."""
    with ctx.db.read_session() as s:
        rows = list(s.scalars(select(EvaluationChunkRow)
                              .where(EvaluationChunkRow.evaluation_id == evaluation_id)
                              .order_by(EvaluationChunkRow.chunk_index)))
        out = []
        for k, r in enumerate(rows):
            if r.chunk_index != k:
                break
            out.append(decode_chunk(r.data))
    return out


# --------------------------------------------------------------------------- run
def campaign(model: CutInGMM, factory: suts.SutFactory, spec: CampaignSpec, *, runner: Runner,
             progress: ProgressFn | None = None,
             on_chunk: Callable[[ChunkResult], None] | None = None,
             stored: Sequence[ChunkResult] = (),
             executor: Executor | None = None) -> CampaignResult:
    """``sampler.campaign.evaluate`` for a spec (the one call the job and the CLI make)."""
    result: CampaignResult = _campaign_face().evaluate(
        model, runner, constraints=spec.constraints or None, n=spec.n, rhw=spec.rhw,
        max_runs=spec.max_runs, seed=spec.seed, batch_size=spec.batch_size,
        progress=progress, on_chunk=on_chunk, stored=list(stored), executor=executor,
        sut=spec.sut, adapt=spec.adapt, band_step=spec.band_step, roulette=spec.roulette,
        final_alpha=spec.final_alpha)
    return result


def run_job(ctx: ServiceContext, evaluation_id: str, *, cancel: threading.Event | None = None,
            stop: threading.Event | None = None,
            progress: ProgressFn | None = None, share: Share | None = None) -> str:
    """Run (or resume) an evaluation to its end; its final status (done, failed, cancelled,
    deleted, or interrupted when ``stop`` was set: it stays running and resumes at the
    next start). ``share``: the job's turn on the workers (``app.jobs.fair``): each part
    of a chunk waits for it, and a cancelled job submits no more parts."""
    with ctx.db.session() as s:
        row = s.get(EvaluationRow, evaluation_id)
        if row is None:
            return "deleted"
        if row.status == "done":
            return "done"
        row.status, row.error, row.updated_at = "running", None, utcnow()
        spec = CampaignSpec.from_dict(jsonconv.decode(row.spec))
        model_id = row.model_id
    try:
        model = ctx.model(model_id)
        entry = suts.resolve(spec.sut, allow_import=False, field="sut")
        factory = suts.make_factory(entry, spec.sut_params, field="sut_params")
        runner = runner_for(ctx, factory, spec.settings, spec.risk)
        stored = stored_chunks(ctx, evaluation_id)
        with ctx.db.session() as s:  # drop what a gap made unusable, and its runs
            s.execute(sql_delete(EvaluationChunkRow).where(
                EvaluationChunkRow.evaluation_id == evaluation_id,
                EvaluationChunkRow.chunk_index >= len(stored)))
            s.execute(sql_delete(EvaluationRunRow).where(
                EvaluationRunRow.evaluation_id == evaluation_id,
                EvaluationRunRow.chunk_index >= len(stored)))
            ev = s.get(EvaluationRow, evaluation_id)
            if ev is not None:
                ev.runs_done = sum(c.n for c in stored)
        log.info("evaluation %s: %d chunks stored, running the rest", evaluation_id,
                 len(stored))

        def halt() -> None:
            if (cancel is not None and cancel.is_set()) or (stop is not None
                                                             and stop.is_set()):
                raise Cancelled()

        def on_chunk(chunk: Any) -> None:
            if not store_chunk(ctx, evaluation_id, chunk, spec.batch_size) \
                    and not _exists(ctx, evaluation_id):
                raise Cancelled()

        def tell(stage: str, done: int, total: int) -> None:
            if progress is not None:
                progress(stage, done, total)
            halt()

        # parts of each chunk go through the fair executor (inline without a pool): each
        # waits for the job's turn, and none starts once the job is cancelled
        executor = FairExecutor(ctx.executor.futures_executor() or InlineFutures(), share,
                                _AnyOf(cancel, stop))
        result = campaign(model, factory, spec, runner=runner, progress=tell,
                          on_chunk=on_chunk, stored=stored, executor=executor)
        summary = jsonconv.encode(result.summary())
    except (Cancelled, JobCancelled):
        if not _exists(ctx, evaluation_id):
            return "deleted"
        if cancel is not None and cancel.is_set():
            return _finish(ctx, evaluation_id, "cancelled", None)
        log.info("evaluation %s interrupted by shutdown; resumes at next start",
                 evaluation_id)
        return "interrupted"
    except Exception as exc:
        log.exception("evaluation %s failed", evaluation_id)
        msg = getattr(exc, "message", None) or str(exc)
        return _finish(ctx, evaluation_id, "failed", f"{type(exc).__name__}: {msg}")
    return _finish(ctx, evaluation_id, "done", None, summary=summary)


class _AnyOf:
    """Set when any of the events is."""

    def __init__(self, *events: threading.Event | None) -> None:
        self.events = [e for e in events if e is not None]

    def is_set(self) -> bool:
        return any(e.is_set() for e in self.events)


def _exists(ctx: ServiceContext, evaluation_id: str) -> bool:
    with ctx.db.read_session() as s:
        return s.get(EvaluationRow, evaluation_id) is not None


def _finish(ctx: ServiceContext, evaluation_id: str, status: str, error: str | None,
            summary: dict[str, Any] | None = None) -> str:
    with ctx.db.session() as s:
        row = s.get(EvaluationRow, evaluation_id)
        if row is None:
            return "deleted"
        row.status, row.error, row.updated_at = status, error, utcnow()
        if summary is not None:
            row.summary = summary
        if status == "done":
            row.finished_at = utcnow()
    log.info("evaluation %s: %s%s", evaluation_id, status, f" ({error})" if error else "")
    return status


def job(ctx: ServiceContext) -> Callable[[str, threading.Event, threading.Event, Share], str]:
    """The job manager's entry for evaluations."""
    return lambda eid, cancel, stop, share: run_job(ctx, eid, cancel=cancel, stop=stop,
                                                    share=share)


def active_ids(ctx: ServiceContext) -> list[str]:
    """Evaluations to resume at start (queued or running), oldest first."""
    with ctx.db.read_session() as s:
        return list(s.scalars(select(EvaluationRow.id)
                              .where(EvaluationRow.status.in_(repo.ACTIVE))
                              .order_by(EvaluationRow.created_at, EvaluationRow.id)))


# --------------------------------------------------------------------------- read
def get(ctx: ServiceContext, evaluation_id: str,
        field: str = "path.evaluation_id") -> EvaluationRow:
    with ctx.db.read_session() as s:
        row = s.get(EvaluationRow, evaluation_id)
        if row is None:
            raise NotFound(f"evaluation {evaluation_id!r} not found", field=field)
        return row


def list_all(ctx: ServiceContext) -> list[EvaluationRow]:
    with ctx.db.read_session() as s:
        return list(s.scalars(select(EvaluationRow).order_by(EvaluationRow.created_at,
                                                             EvaluationRow.id)))


def _p_bounds(row: EvaluationRow) -> float | None:
    summary = jsonconv.decode(row.summary) if row.summary else None
    pb = summary.get("p_bounds") if isinstance(summary, dict) else None
    return float(pb) if isinstance(pb, int | float) and pb > 0 else None


def stored_summary(row: EvaluationRow) -> dict[str, Any] | None:
    """The row's summary (numbers decoded) with its verdict, ``warnings`` and
    ``reliable``, recomputed from its own figures (``sampler.campaign.reliability``): the
    same as a new campaign's, and there for an evaluation stored before the fields."""
    if not row.summary:
        return None
    from sampler.campaign import with_verdict

    return with_verdict(jsonconv.decode(row.summary))


def describe(ctx: ServiceContext, evaluation_id: str) -> EvaluationStatus:
    """Status, progress, the spec and (once done) the campaign's summary (``spec`` and
    ``summary`` in the service's JSON form: ``jsonconv.decode`` gives the numbers)."""
    row = get(ctx, evaluation_id)
    with ctx.db.read_session() as s:
        chunks, collisions, simulated = s.execute(
            select(func.count(EvaluationChunkRow.id),
                   func.coalesce(func.sum(EvaluationChunkRow.collisions), 0),
                   select(func.count(EvaluationRunRow.id))
                   .where(EvaluationRunRow.evaluation_id == evaluation_id)
                   .scalar_subquery())
            .where(EvaluationChunkRow.evaluation_id == evaluation_id)).one()
    spec = jsonconv.decode(row.spec)
    done = row.status == "done"
    summary = stored_summary(row)
    return EvaluationStatus(
        id=row.id, status=row.status, sut=row.sut, model=row.model_id,
        seed=row.seed, constraints=spec.get("constraints", []), spec=jsonconv.encode(spec),
        runs_planned=row.runs_planned, runs_done=row.runs_done,
        # with the stop rule the campaign usually ends before max_runs: progress then
        # says how much of the budget was used
        progress=1.0 if done else min(1.0, row.runs_done / max(1, row.runs_planned)),
        chunks_done=int(chunks), collisions_so_far=int(collisions),
        runs_simulated=int(simulated),
        summary=None if summary is None else jsonconv.encode(summary), error=row.error,
        href_runs=f"/evaluations/{row.id}/runs",
        created_at=row.created_at.isoformat(), updated_at=row.updated_at.isoformat(),
        finished_at=row.finished_at.isoformat() if row.finished_at else None,
    )


@dataclass(frozen=True)
class RunFilter:
    ranges: tuple[tuple[str, float | None, float | None], ...] = ()
    flags: tuple[tuple[str, bool], ...] = ()
    vs_careful: tuple[str, ...] = ()
    #: not query parameters (the dashboard's): only the runs of these chunks (None: of
    #: any), and none of those of ``skip_chunks``
    chunks: tuple[int, ...] | None = None
    skip_chunks: tuple[int, ...] = ()


def run_filter(items: Sequence[tuple[str, str]], vs_careful: Sequence[str] = (),
               where: str = "query") -> RunFilter:
    """Filters of ``/runs`` from ``name=value`` pairs: ``<field>_min``/``_max`` on
    ``RANGE_FIELDS``, ``<flag>=true|false`` on ``FLAG_FIELDS``, ``vs_careful`` (repeatable).
    Anything else is an ``InvalidInput`` naming it."""
    parsed = parse_filters(items, RANGE_FIELDS, FLAG_FIELDS, "vs_careful", where)
    bad = [v for v in vs_careful if v not in VS_CAREFUL]
    if bad:
        raise InvalidInput(f"vs_careful: unknown value {bad[0]!r}; valid: "
                           f"{', '.join(VS_CAREFUL)}", field=f"{where}.vs_careful")
    return RunFilter(parsed.ranges, parsed.flags, tuple(vs_careful))


def check_order(order_by: str, desc: bool | None, where: str = "query") -> bool:
    if order_by not in ORDER_FIELDS:
        raise InvalidInput(f"order_by: unknown field {order_by!r}; valid: "
                           f"{', '.join(ORDER_FIELDS)}", field=f"{where}.order_by")
    return (order_by != "run") if desc is None else bool(desc)


def _column(name: str) -> Any:
    return EvaluationRunRow.weight_raw if name == "weight" else getattr(EvaluationRunRow, name)


#: a run's TTR-risk fields: NaN in the simulator's arrays when the evaluation was made
#: without ``risk``; null ("no value", docs/api.md) in what the service gives out
RISK_FIELDS = ("r_dep_peak", "r_ind_peak", "r_dep_time_above")


def run_record(r: EvaluationRunRow, pb: float | None) -> dict[str, Any]:
    rec: dict[str, Any] = dict(jsonconv.decode(r.record))
    for name in RISK_FIELDS:  # also for runs stored before (they hold NaN)
        v = rec.get(name)
        if isinstance(v, float) and math.isnan(v):
            rec[name] = None
    rec["weight"] = None if pb is None else rec.get("weight_raw", r.weight_raw) / pb
    return rec


def _conditions(evaluation_id: str, flt: RunFilter) -> list[Any]:
    conds: list[Any] = [EvaluationRunRow.evaluation_id == evaluation_id]
    for name, lo, hi in flt.ranges:
        col = _column(name)
        if lo is not None:
            conds.append(col >= lo)
        if hi is not None:
            conds.append(col <= hi)
    for name, value in flt.flags:
        conds.append(_column(name).is_(value))
    if flt.vs_careful:
        conds.append(EvaluationRunRow.vs_careful.in_(flt.vs_careful))
    if flt.chunks is not None:
        conds.append(EvaluationRunRow.chunk_index.in_(flt.chunks))
    if flt.skip_chunks:
        conds.append(EvaluationRunRow.chunk_index.not_in(flt.skip_chunks))
    return conds


def page_runs(ctx: ServiceContext, evaluation_id: str, flt: RunFilter, offset: int,
              limit: int, *, order_by: str = "impact_speed",
              desc: bool = True) -> tuple[int, list[dict[str, Any]]]:
    """(matching runs, one page of their records). ``weight`` (w / P(B)) is null until
    the evaluation is done (P(B) comes with its summary)."""
    row = get(ctx, evaluation_id)
    pb = _p_bounds(row)
    conds = _conditions(evaluation_id, flt)
    col = _column(order_by)
    ordering = [col.is_(None), col.desc() if desc else col.asc(), EvaluationRunRow.run]
    with ctx.db.read_session() as s:
        total = int(s.scalar(select(func.count(EvaluationRunRow.id)).where(*conds)) or 0)
        rows = list(s.scalars(select(EvaluationRunRow).where(*conds).order_by(*ordering)
                              .offset(offset).limit(limit)))
        return total, [run_record(r, pb) for r in rows]


def weight_sum(ctx: ServiceContext, evaluation_id: str, flt: RunFilter) -> float | None:
    """The sum of the ``weight`` (w / P(B)) of the runs matching ``flt``; None until the
    evaluation is done. Over the collided runs of the counted chunks it is n * P (the
    estimate's numerator, docs/evaluation.md)."""
    pb = _p_bounds(get(ctx, evaluation_id))
    if pb is None:
        return None
    with ctx.db.read_session() as s:
        total = s.scalar(select(func.coalesce(func.sum(EvaluationRunRow.weight_raw), 0.0))
                         .where(*_conditions(evaluation_id, flt)))
    return float(total or 0.0) / pb


def pilot_chunks(ctx: ServiceContext, evaluation_id: str) -> tuple[int, ...]:
    """The chunks of a finished evaluation that its estimate leaves out: the pilot chunks
    of a cross-entropy campaign (each stored with ``counted`` false; docs/evaluation.md,
    "what counts"). () when the summary's ``pilot_runs`` is 0 (every chunk counts, also
    a campaign that never reached its final stage) or before the evaluation is done. The
    stored chunks are read in order only until the pilot ones hold ``pilot_runs`` draws."""
    row = get(ctx, evaluation_id)
    summary = jsonconv.decode(row.summary) if row.summary else None
    pilot = summary.get("pilot_runs") if isinstance(summary, dict) else None
    if not isinstance(pilot, int | float) or pilot <= 0:
        return ()
    out: list[int] = []
    seen = 0
    with ctx.db.read_session() as s:
        sizes = list(s.execute(select(EvaluationChunkRow.chunk_index, EvaluationChunkRow.n_runs)
                               .where(EvaluationChunkRow.evaluation_id == evaluation_id)
                               .order_by(EvaluationChunkRow.chunk_index)))
        for index, n_runs in sizes:
            if seen >= pilot:
                break
            data = s.scalar(select(EvaluationChunkRow.data).where(
                EvaluationChunkRow.evaluation_id == evaluation_id,
                EvaluationChunkRow.chunk_index == index))
            if data is not None and not decode_chunk(data).counted:
                out.append(int(index))
                seen += int(n_runs)
    return tuple(out)


def run_by_index(ctx: ServiceContext, evaluation_id: str, run: int) -> dict[str, Any] | None:
    """The record of simulated run ``run`` (None when there is no such run)."""
    row = get(ctx, evaluation_id)
    with ctx.db.read_session() as s:
        r = s.scalar(select(EvaluationRunRow).where(
            EvaluationRunRow.evaluation_id == evaluation_id, EvaluationRunRow.run == run))
        return None if r is None else run_record(r, _p_bounds(row))


#: the runs exported when no filter is given: the failing (collided) ones
FAILING = RunFilter(flags=(("collided", True),))


def failing_runs(ctx: ServiceContext, evaluation_id: str,
                 flt: RunFilter = FAILING) -> Iterator[dict[str, Any]]:
    """Every run of an evaluation matching ``flt`` (default: the collided ones), highest
    impact speed first."""
    offset = 0
    while True:
        _, page = page_runs(ctx, evaluation_id, flt, offset, 500,
                            order_by="impact_speed", desc=True)
        if not page:
            return
        yield from page
        offset += len(page)


def rebuild(params: Mapping[str, float], lane_width: float, seed: int, run: int,
            evaluation_id: str) -> ConcreteScenario | None:
    """A run's concrete scenario rebuilt from its parameter vector (the builder is
    deterministic); None when the builder refuses the vector."""
    from sampler.scenario import score_vector

    _, scenario = score_vector(dict(params), index=run, lane_width=lane_width, seed=seed,
                               provenance={"evaluation": evaluation_id, "run": run},
                               score=False, include_scenario=True)
    return scenario


def export(ctx: ServiceContext, evaluation_id: str, fmt: str, out: Path,
           mode: str | None = None, flt: RunFilter | None = None) -> Path:
    """Write the runs of a finished evaluation matching ``flt`` (None: the failing,
    i.e. collided, runs) to ``out``: ``json`` (one document: the summary and each run's
    record with its concrete scenario), ``xosc`` (OpenSCENARIO, test mode: the ego is the
    system under test) or ``commonroad``."""
    if fmt not in EXPORT_FORMATS:
        raise InvalidInput(f"format: unknown format {fmt!r}; choose one of "
                           f"{', '.join(EXPORT_FORMATS)}", field="query.format")
    row = get(ctx, evaluation_id)
    if row.status != "done":
        raise Conflict(f"evaluation {evaluation_id} is {row.status}; export needs a "
                       "finished evaluation", field="path.evaluation_id")
    lane_width = domain.model_lane_width(ctx.model(row.model_id))
    summary = stored_summary(row) or {}

    def items() -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
        for rec in failing_runs(ctx, evaluation_id, FAILING if flt is None else flt):
            params = {k: float(rec[k]) for k in PARAM_NAMES}
            scenario = rebuild(params, lane_width, row.seed, int(rec["run"]), evaluation_id)
            if scenario is not None:
                yield scenario, rec

    if fmt == "json":
        runs = [{"run": rec, "scenario": sc.to_dict()} for sc, rec in items()]
        out.write_text(jsonconv.dumps({"format": "scengen.evaluation-failures/1",
                                       "evaluation": evaluation_id, "sut": row.sut,
                                       "model": row.model_id, "summary": summary,
                                       "runs": runs}))
        return out
    from app.exports import ExportError, build_manifest, export_catalogue

    with ctx.db.read_session() as s:
        model_hash = repo.get_model(s, row.model_id, field="model").model_hash
    spec = jsonconv.decode(row.spec)
    manifest = build_manifest(
        seed=row.seed, model_hash=model_hash,
        sampler_settings={"method": "campaign", "batch_size": spec.get("batch_size")},
        constraints=list(spec.get("constraints", [])), p_region=None,
        extra={"evaluation": evaluation_id, "sut": row.sut, "model_id": row.model_id,
               "failing_runs": summary.get("collisions")})

    def flat() -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
        for sc, rec in items():
            yield sc, {"scenario_id": rec["run"], "run": rec["run"],
                       "impact_speed": rec.get("impact_speed"),
                       "r_dep_peak": rec.get("r_dep_peak"),
                       "vs_careful": rec.get("vs_careful"), "weight": rec.get("weight")}

    try:
        return export_catalogue(fmt, flat(), manifest, out,
                                mode=(mode or "test") if fmt == "xosc" else None)
    except ExportError as exc:
        raise ServiceError(f"export of evaluation {evaluation_id} failed: {exc}") from None


def delete(ctx: ServiceContext, evaluation_id: str) -> None:
    get(ctx, evaluation_id)
    with ctx.db.session() as s:
        s.execute(sql_delete(EvaluationRunRow)
                  .where(EvaluationRunRow.evaluation_id == evaluation_id))
        s.execute(sql_delete(EvaluationChunkRow)
                  .where(EvaluationChunkRow.evaluation_id == evaluation_id))
        s.execute(sql_delete(EvaluationRow).where(EvaluationRow.id == evaluation_id))
