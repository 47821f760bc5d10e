"""Run a catalogue job to the end, from whatever chunks are already stored.

The job's state is in the database only: the catalogue row (spec, status, P(A)) and one
row per finished chunk. ``CatalogueRunner.run`` computes the chunks that are missing and
stores each one as soon as it is finished (``repository.store_chunk``: one transaction,
unique chunk index). A process killed at any moment loses at most the chunks in flight;
running the job again completes it with exactly the content an uninterrupted run has,
because chunk i depends only on (spec, i).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import wait
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from app import domain, jsonconv
from app.db import chunkfile
from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow, utcnow
from app.jobs import joblock
from app.jobs.chunk import CatalogueSpec, ChunkStopped, region_seed
from app.jobs.executors import ChunkExecutor
from app.jobs.fair import JobCancelled, Share

if TYPE_CHECKING:  # annotations only: app.schemas imports the sampler
    from app.schemas import PRegionJSON

log = logging.getLogger("scengen.jobs")

Progress = Callable[[int, int], None]  # (scenarios done, scenarios in total)
#: a stage of the work with its counts: (name, done, total), as ``sampler``'s ProgressFn
Stage = Callable[[str, int, int], None]
#: seconds between two writes of the same stage's counts (a new stage is written at once)
STAGE_EVERY = 0.5
#: seconds between two looks at the cancel flag and the stage file while a worker
#: estimates P(A)
REGION_POLL = 0.25
_ESTIMATING = "estimating P(A): "
T = TypeVar("T")


@contextlib.contextmanager
def _turn(share: Share | None, halt: _Either) -> Iterator[None]:
    """Hold one of the job's slots for the block (nothing without a share)."""
    if share is None:
        yield
        return
    with share.slot(halt):
        yield


class _Either:
    """Set when any of the given events is set (the executors' ``cancel`` check)."""

    def __init__(self, *events: threading.Event | None) -> None:
        self.events = [e for e in events if e is not None]

    def is_set(self) -> bool:
        return any(e.is_set() for e in self.events)


def worker_spec(row: CatalogueRow, model_json: str) -> CatalogueSpec:
    """The executor-side spec of a catalogue row (adds the model's JSON and P(A))."""
    spec = dict(row.spec)
    p_region = jsonconv.decode(row.p_region) if row.p_region else None
    estimate = p_region.get("estimate") if isinstance(p_region, dict) else None
    return CatalogueSpec(
        n=row.n, seed=row.seed, chunk_size=row.chunk_size, model_json=model_json,
        constraints=tuple(spec.get("constraints", ())), method=spec.get("method", "auto"),
        score=bool(spec.get("score", True)),
        wagner_scan=bool(spec.get("wagner_scan", False)),
        store_trajectories=bool(spec.get("store_trajectories", True)),
        p_region=None if estimate is None else float(estimate),
        region=row.p_region,
    )


def estimate_region(spec: CatalogueSpec, stage: Stage | None = None) -> PRegionJSON:
    """P(A) of the catalogue's region: one estimate from the catalogue's seed, with the
    "model" interval and the rates when the model has replicates and an exposure.
    ``stage`` hears the estimator's stages (pilot, plain Monte Carlo, subset-is, ...)."""
    model = domain.load_model(spec.model_json)
    constraints = domain.parse_constraints(spec.constraints)
    seed = region_seed(spec.seed)
    p_region = domain.estimate_region(model, constraints, seed, progress=stage)
    if stage is not None and (model.bootstrap_ or model.exposure_):
        stage("model interval and rates", 0, 1)
    encoded: PRegionJSON = jsonconv.encode(
        domain.region_uncertainty(model, constraints, p_region, n_samples=spec.n))
    return encoded


def needs_refinement(p_region: Mapping[str, Any]) -> bool:
    """Whether the P(A) dict has a model interval with an end left unresolved."""
    interval = p_region.get("model_interval")
    return isinstance(interval, dict) and not (interval.get("lower_resolved", True)
                                               and interval.get("upper_resolved", True))


def refine_region(spec: CatalogueSpec, p_region: Mapping[str, Any]) -> PRegionJSON | None:
    """The catalogue's P(A) dict with its model interval refined when that interval left an
    end unresolved (rare regions: every unresolved bootstrap replicate gets its own
    subset-is run, ``sampler.rates.pooled_interval(per_replicate=True)``); None when there
    is nothing to refine. Run once the scenarios are stored: it takes 0.4-1 s per
    unresolved replicate (tens of seconds for ``btn>0.7`` on the TNO model)."""
    if not needs_refinement(p_region):
        return None
    model = domain.load_model(spec.model_json)
    constraints = domain.parse_constraints(spec.constraints)
    refined: PRegionJSON = jsonconv.encode(domain.region_uncertainty(
        model, constraints, jsonconv.decode(p_region), n_samples=spec.n, per_replicate=True))
    return refined


class _Refine:
    """``refine(spec, p_region)`` as a region function ``(spec, stage)`` (picklable when
    ``refine`` is: it is sent to a worker)."""

    def __init__(self, refine: Callable[[CatalogueSpec, Mapping[str, Any]], PRegionJSON | None],
                 p_region: Mapping[str, Any]) -> None:
        self.refine = refine
        self.p_region = p_region

    def __call__(self, spec: CatalogueSpec, stage: Stage) -> PRegionJSON | None:
        return self.refine(spec, self.p_region)


def region_in_worker(fn: Callable[[CatalogueSpec, Stage], T], spec: CatalogueSpec,
                     folder: str) -> T:
    """Run ``fn(spec, stage)`` in an executor's worker: the stages are written to the
    job's stage file (``chunkfile.write_stage``, at most every ``STAGE_EVERY`` s per
    stage), and at each stage a stop request (the job was cancelled, its catalogue
    deleted) ends the work with ``ChunkStopped``."""
    existed = os.path.isdir(folder)
    stages = _StageFile(Path(folder))

    def stage(name: str, done: int, total: int) -> None:
        stages.estimating(name, done, total)
        if chunkfile.stop_requested(folder, existed):
            raise ChunkStopped("the job was cancelled during its P(A) estimate")

    return fn(spec, stage)


def scenarios_done(n: int, chunk_size: int, stored: set[int], folder: Path) -> int:
    """Scenarios of the stored chunks (of a catalogue of ``n`` in chunks of ``chunk_size``)
    plus those the workers report done in the chunks being computed
    (``chunkfile.read_progress``)."""
    n_chunks = (n + chunk_size - 1) // chunk_size

    def size(i: int) -> int:
        return min(n, (i + 1) * chunk_size) - i * chunk_size

    partial = sum(min(k, size(i)) for i, k in chunkfile.read_progress(folder).items()
                  if i not in stored and 0 <= i < n_chunks)
    return sum(size(i) for i in stored if 0 <= i < n_chunks) + partial


class _Meter:
    """Calls ``progress(scenarios done, n)`` when a chunk is stored and, from a ticker
    thread, every ``PROGRESS_TICK`` s while chunks are computed (per scenario)."""

    def __init__(self, spec: CatalogueSpec, folder: Path, stored: set[int],
                 progress: Progress | None) -> None:
        self.spec, self.folder, self.progress = spec, folder, progress
        self.done = set(stored)
        self.lock = threading.Lock()
        self.halt = threading.Event()
        self.last = -1
        self._report()
        self.thread: threading.Thread | None = None
        if progress is not None:
            self.thread = threading.Thread(target=self._tick, name="catalogue-progress",
                                           daemon=True)
            self.thread.start()

    def _report(self) -> None:
        if self.progress is None:
            return
        with self.lock:
            n = scenarios_done(self.spec.n, self.spec.chunk_size, self.done, self.folder)
            if n > self.last:  # never backwards (a chunk between its file and its row)
                self.last = n
                self.progress(n, self.spec.n)

    def _tick(self) -> None:
        while not self.halt.wait(PROGRESS_TICK):
            self._report()

    def stored(self, index: int) -> None:
        with self.lock:
            self.done.add(index)
        self._report()

    def close(self) -> None:
        self.halt.set()
        if self.thread is not None:
            self.thread.join(timeout=5)


#: seconds between two progress reports of the runner while chunks are computed
PROGRESS_TICK = 0.5


class _StageFile:
    """Writes the job's stage to its folder (``chunkfile.write_stage``) for the status: a
    new stage at once, the counts of the same stage at most every ``STAGE_EVERY`` s."""

    def __init__(self, folder: Path, listener: Stage | None = None) -> None:
        self.folder = folder
        self.listener = listener
        self.name: str | None = None
        self.written = 0.0

    def __call__(self, name: str, done: int | None = None, total: int | None = None) -> None:
        now = time.monotonic()
        if name == self.name and now - self.written < STAGE_EVERY:
            return
        self.name, self.written = name, now
        chunkfile.write_stage(self.folder, name, done, total)

    def estimating(self, name: str, done: int, total: int) -> None:
        """A stage of the P(A) estimate (also told to the listener, e.g. the CLI's bars)."""
        self(f"{_ESTIMATING}{name}", done, total)
        if self.listener is not None:
            self.listener(f"P(A): {name}", done, total)

    def clear(self) -> None:
        chunkfile.clear_stage(self.folder)


class CatalogueRunner:
    """Runs catalogue jobs against one database/data dir with one executor."""

    def __init__(self, db: Database, data_dir: Path, executor: ChunkExecutor,
                 region: Callable[[CatalogueSpec, Stage], PRegionJSON] = estimate_region,
                 refine: Callable[[CatalogueSpec, Mapping[str, Any]], PRegionJSON | None]
                 = refine_region) -> None:
        self.db = db
        self.data_dir = Path(data_dir)
        self.executor = executor
        self.region = region
        self.refine = refine

    def run(self, catalogue_id: str, *, cancel: threading.Event | None = None,
            stop: threading.Event | None = None, progress: Progress | None = None,
            note: Callable[[str], None] | None = None, stage: Stage | None = None,
            share: Share | None = None, only_active: bool = False) -> str:
        """Finish the catalogue; return its final status (done, failed, cancelled,
        deleted, or interrupted when ``stop`` was set: the service is shutting down and
        the job stays ``running``, to be resumed at the next start). Errors of the job
        end in status ``failed`` with the message kept. ``progress`` hears the scenarios
        done, ``stage`` the stages of the P(A) estimate, ``note`` why the job is still
        running after its scenarios are stored. ``share``: the job's turn on the workers
        (``app.jobs.fair``; the service's jobs share them chunk by chunk), also held for
        the P(A) estimate and its refinement.

        The job's lock (``app.jobs.joblock``) is held while it runs: a job that another
        process runs raises ``JobBusy`` and is left unchanged. ``only_active`` (the
        service's jobs): a job no longer queued or running once the lock is taken (its
        previous holder ended it) is left as it is. Ctrl-C (the CLI) leaves the job
        ``cancelled`` before its lock is released, so that a service waiting for the lock
        does not take it over."""
        with self.db.session() as s:
            repo.get_catalogue(s, catalogue_id)  # an unknown id: LookupError, no lock file
        lock = joblock.acquire(self.data_dir, catalogue_id)
        try:
            return self._run(catalogue_id, cancel, stop, progress, note, stage, share,
                             only_active)
        except KeyboardInterrupt:
            with self.db.session() as s:
                row = s.get(CatalogueRow, catalogue_id)
                if row is not None and row.status in repo.ACTIVE:
                    row.status, row.updated_at = "cancelled", utcnow()
            raise
        finally:
            joblock.release(lock)

    def _run(self, catalogue_id: str, cancel: threading.Event | None,
             stop: threading.Event | None, progress: Progress | None,
             note: Callable[[str], None] | None, stage: Stage | None,
             share: Share | None, only_active: bool) -> str:
        halt = _Either(cancel, stop)
        with self.db.session() as s:
            row = repo.get_catalogue(s, catalogue_id)
            if row.status == "done" or (only_active and row.status not in repo.ACTIVE):
                return str(row.status)
            model_json = repo.get_model(s, row.model_id, field="model").model_json
            spec = worker_spec(row, model_json)
            row.status = "running"
            row.error = None
            row.updated_at = utcnow()
            need_region = row.p_region is None
            done = repo.stored_chunk_indices(s, catalogue_id)
        total = spec.n_chunks
        log.info("catalogue %s: %d of %d chunks stored, running the rest on %s",
                 catalogue_id, len(done), total, self.executor.name)
        folder = chunkfile.progress_dir(self.data_dir, catalogue_id)
        chunkfile.clear_stop(folder)  # a job cancelled before is run again
        meter = _Meter(spec, folder, done, progress)
        stages = _StageFile(folder, stage)

        def estimating(name: str, done: int, total: int) -> None:
            stages.estimating(name, done, total)
            if halt.is_set():  # cancelled (or shutting down) during the P(A) estimate
                raise JobCancelled()

        try:
            if need_region:
                stages.estimating("starting", 0, 1)
                with _turn(share, halt):
                    p_region = self._off_thread(self.region, spec, folder, estimating,
                                                stages, halt)
                with self.db.session() as s:
                    row = repo.get_catalogue(s, catalogue_id)
                    row.p_region = dict(p_region)  # the JSON column: a plain dict
                    spec = worker_spec(row, model_json)
            spec = dataclasses.replace(spec, progress_dir=str(folder))
            todo = [i for i in range(total) if i not in done]
            for i in todo:  # what an interrupted run reported is redone from 0
                chunkfile.clear_progress(folder, i)
            stages("sampling and scoring")
            for result in self.executor.run(spec, todo, halt, share):
                with self.db.session() as s:
                    ok = repo.store_chunk(s, self.data_dir, catalogue_id, result.index,
                                          result.rows, result.blob, result.sha256,
                                          result.diagnostics)
                chunkfile.clear_progress(folder, result.index)
                if not ok and not self._exists(catalogue_id):
                    repo.remove_catalogue_files(self.data_dir, catalogue_id)
                    return "deleted"
                meter.stored(result.index)
            if cancel is not None and cancel.is_set():
                return self._finish(catalogue_id, "cancelled", None)
            if stop is not None and stop.is_set():
                log.info("catalogue %s interrupted by shutdown; resumes at next start",
                         catalogue_id)
                return "interrupted"
            with self.db.session() as s:
                missing = total - len(repo.stored_chunk_indices(s, catalogue_id))
            if missing:
                return self._finish(catalogue_id, "failed", f"{missing} chunks missing")
            with _turn(share, halt):
                self._refine_region(catalogue_id, spec, note, stages, halt)
            return self._finish(catalogue_id, "done", None)
        except (JobCancelled, ChunkStopped):
            return self._halted(catalogue_id, stop)
        except Exception as exc:
            if not self._exists(catalogue_id):  # deleted under the job: not a failure
                log.info("catalogue %s deleted while its job ran (%s)", catalogue_id,
                         type(exc).__name__)
                return "deleted"
            log.exception("catalogue %s failed", catalogue_id)
            return self._finish(catalogue_id, "failed", f"{type(exc).__name__}: {exc}")
        finally:
            meter.close()
            stages.clear()
            if not self._exists(catalogue_id):
                # what the job wrote after the deletion removed the folder (its progress and
                # stage files) goes too: a deleted catalogue leaves nothing behind
                repo.remove_catalogue_files(self.data_dir, catalogue_id)

    def _off_thread(self, fn: Callable[[CatalogueSpec, Stage], T], spec: CatalogueSpec,
                    folder: Path, stage: Stage, stages: _StageFile, halt: _Either) -> T:
        """``fn(spec, stage)`` (the P(A) estimate, the refinement of its interval) on
        the executor's workers when it has any, else here. In the service the estimate
        and the model interval are seconds of numerical work per catalogue; run in the
        job's thread they held the service process (its GIL) while the requests waited:
        /health p99 915 ms under the load test, 8 jobs estimating at once. In a worker the
        stages go through the job's stage file (relayed to the listener, e.g. the CLI's
        bars) and a cancelled job's stop file ends the work at its next stage."""
        pool = self.executor.futures_executor()
        if pool is None:
            return fn(spec, stage)
        future = pool.submit(region_in_worker, fn, spec, str(folder))
        relayed: dict[str, Any] | None = None
        try:
            while True:
                done, _ = wait([future], timeout=REGION_POLL)
                if done:
                    return future.result()
                if halt.is_set():  # cancelled or shutting down: the worker stops too
                    raise JobCancelled()
                current = chunkfile.read_stage(folder)
                if stages.listener is not None and current is not None \
                        and current != relayed and current["name"].startswith(_ESTIMATING):
                    relayed = current
                    stages.listener(f"P(A): {current['name'].removeprefix(_ESTIMATING)}",
                                    current.get("done") or 0, current.get("total") or 0)
        except BaseException:  # halted, Ctrl-C in the CLI, ...: the worker stops as well
            if not future.cancel():  # running already: it stops at its next stage
                chunkfile.request_stop(folder)
            raise

    def _refine_region(self, catalogue_id: str, spec: CatalogueSpec,
                       note: Callable[[str], None] | None, stage: _StageFile,
                       halt: _Either) -> None:
        """Refine the stored model interval (``refine_region``) before the job is done;
        ``note`` and the stage file say why the job is still running."""
        with self.db.session() as s:
            current = repo.get_catalogue(s, catalogue_id).p_region
        if current is not None and needs_refinement(current):
            why = ("all scenarios stored; refining the model interval of P(A): one subset-is "
                   "run per unresolved bootstrap replicate (about 0.5-1 s each)")
            stage(why)
            if note is not None:
                note(why)
        refined = None if current is None else self._off_thread(
            _Refine(self.refine, current), spec, folder=chunkfile.progress_dir(
                self.data_dir, catalogue_id), stage=lambda *_: None, stages=stage, halt=halt)
        if refined is not None:
            with self.db.session() as s:
                repo.get_catalogue(s, catalogue_id).p_region = dict(refined)

    def request_stop(self, catalogue_id: str) -> None:
        """Have the workers give up the catalogue's chunks in flight (its job was
        cancelled): ``chunkfile.request_stop``; the next ``run`` forgets it."""
        chunkfile.request_stop(chunkfile.progress_dir(self.data_dir, catalogue_id))

    def _halted(self, catalogue_id: str, stop: threading.Event | None) -> str:
        """The status of a job stopped before its end: deleted, interrupted (the service
        stops: left ``running``, to resume at the next start) or cancelled."""
        if not self._exists(catalogue_id):
            log.info("catalogue %s deleted while its job ran (stopped)", catalogue_id)
            return "deleted"
        if stop is not None and stop.is_set():
            log.info("catalogue %s interrupted by shutdown; resumes at next start",
                     catalogue_id)
            return "interrupted"
        return self._finish(catalogue_id, "cancelled", None)

    def _exists(self, catalogue_id: str) -> bool:
        with self.db.session() as s:
            return s.get(CatalogueRow, catalogue_id) is not None

    def _finish(self, catalogue_id: str, status: str, error: str | None) -> str:
        with self.db.session() as s:
            row = s.get(CatalogueRow, catalogue_id)
            if row is None:
                return "deleted"
            row.status = status
            row.error = error
            row.updated_at = utcnow()
            if status == "done":
                row.finished_at = utcnow()
        log.info("catalogue %s: %s%s", catalogue_id, status, f" ({error})" if error else "")
        return status
