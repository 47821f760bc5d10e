"""The service's job queue: jobs of different clients run side by side and share the
workers chunk by chunk (``app.jobs.fair``), so one client's huge job does not hold
everyone else's behind it.

Up to ``running_limit`` jobs run at once, each in its own thread; the next to start is
the oldest queued job of the client with the fewest jobs running (then of the client
whose last job started longest ago). What they share is the
executor's capacity (``FairSlots``, one slot per chunk in flight): a free slot goes to
the waiting client with the fewest slots in use. Catalogues run through
``CatalogueRunner``; the other kinds are given as ``kinds`` (id prefix -> ``JobKind``: how
to run one, which to resume), e.g. the evaluations of ``app.services.evaluations``."""

from __future__ import annotations

import itertools
import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow
from app.jobs.fair import FairSlots, Share
from app.jobs.joblock import JobBusy
from app.jobs.runner import CatalogueRunner
from app.quotas import ClientQuotas, QuotaToken

#: the client of a job resumed at start-up (it has no request)
RESUMED = "(resumed)"
#: jobs running at once unless told otherwise
RUNNING_LIMIT = 8
#: seconds between two tries of the jobs another process runs (``JobBusy``)
ELSEWHERE_POLL = 2.0

log = logging.getLogger("scengen.jobs")


@dataclass(frozen=True)
class JobKind:
    """A kind of job besides catalogues: ``run(id, cancel, stop, share)`` -> final
    status (``share``: the job's turn on the workers, ``app.jobs.fair``), and
    ``pending()`` -> the ids to resume at start."""

    run: Callable[[str, threading.Event, threading.Event, Share], str]
    pending: Callable[[], list[str]]


@dataclass(frozen=True)
class _Queued:
    job_id: str
    client: str
    seq: int


class JobManager:
    def __init__(self, runner: CatalogueRunner,
                 kinds: Mapping[str, JobKind] | None = None, *,
                 running_limit: int = RUNNING_LIMIT, slots: int | None = None) -> None:
        if running_limit < 1:
            raise ValueError(f"running_limit: need at least 1, got {running_limit}")
        self.runner = runner
        self.kinds = dict(kinds or {})
        self.running_limit = running_limit
        #: the workers' capacity shared between clients, chunk by chunk
        self.fair = FairSlots(slots or max(1, runner.executor.capacity()))
        self._queued: list[_Queued] = []
        self._running: dict[str, tuple[threading.Thread, str]] = {}
        self._cancel: dict[str, threading.Event] = {}
        #: per-client quotas of every job kind (``app.quotas``), released as jobs end
        self.quotas = ClientQuotas()
        self._tokens: dict[str, QuotaToken] = {}
        self._lock = threading.Lock()
        self._seq = itertools.count(1)
        self._last_start: dict[str, int] = {}  # client -> seq of its last start
        self._started = False
        self._stop = threading.Event()
        #: jobs another process holds (a CLI's ``catalogue create``): job -> client; tried
        #: again every ELSEWHERE_POLL s and taken over if still unfinished once free
        self._elsewhere: dict[str, str] = {}
        self._watcher: threading.Thread | None = None

    @property
    def db(self) -> Database:
        return self.runner.db

    def start(self, resume: bool = True) -> None:
        with self._lock:
            self._started = True
            self._dispatch()
        if resume:
            with self.db.session() as s:
                ids = [r.id for r in repo.list_catalogues(s) if r.status in repo.ACTIVE]
            for cid in ids:
                log.info("resuming unfinished catalogue %s", cid)
                self.submit(cid)
            for prefix, kind in self.kinds.items():
                for jid in kind.pending():
                    log.info("resuming unfinished %s job %s", prefix, jid)
                    self.submit(jid)

    def submit(self, job_id: str, quota: QuotaToken | None = None,
               client: str | None = None) -> None:
        """Queue a job for ``client`` (default: the quota's client; a job without either
        is a resumed one); ``quota`` (from ``self.quotas``) is released when it ends."""
        who = client if client is not None else quota.client if quota is not None else RESUMED
        with self._lock:
            self._cancel[job_id] = threading.Event()
            if quota is not None:
                self._tokens[job_id] = quota
            self._queued.append(_Queued(job_id, who, next(self._seq)))
            self._dispatch()

    def cancel(self, job_id: str) -> None:
        """Stop a job: a queued one never starts (its quota is given back now), a running
        one stops its chunks."""
        token = None
        with self._lock:
            event = self._cancel.get(job_id)
            if event is not None:
                event.set()
            if job_id in self._running and self._kind_of(job_id) is None:
                self.runner.request_stop(job_id)  # its chunks in flight stop too
            self._elsewhere.pop(job_id, None)
            queued = [q for q in self._queued if q.job_id == job_id]
            if queued:
                self._queued.remove(queued[0])
                self._cancel.pop(job_id, None)
                token = self._tokens.pop(job_id, None)
        self.quotas.release(token)

    def running(self) -> dict[str, str]:
        """The running jobs and their clients."""
        with self._lock:
            return {j: c for j, (_, c) in self._running.items()}

    def queued(self) -> list[str]:
        with self._lock:
            return [q.job_id for q in self._queued]

    def idle(self) -> bool:
        with self._lock:
            return not self._running and not self._queued

    def stop(self) -> None:
        """Stop after the chunks in flight; unfinished jobs stay resumable."""
        self._stop.set()
        with self._lock:
            threads = [t for t, _ in self._running.values()]
        for thread in threads:
            thread.join(timeout=60)
        # the executor belongs to the ServiceContext, which closes it

    def _kind_of(self, job_id: str) -> JobKind | None:
        prefix = job_id.partition("-")[0]
        return self.kinds.get(prefix)

    def _dispatch(self) -> None:
        """Start queued jobs while fewer than ``running_limit`` run (hold ``_lock``): the
        oldest job of the client with the fewest jobs running goes first, of those the
        client whose last job started longest ago."""
        if not self._started:
            return
        while (self._queued and len(self._running) < self.running_limit
               and not self._stop.is_set()):
            counts: dict[str, int] = {}
            for _, who in self._running.values():
                counts[who] = counts.get(who, 0) + 1
            nxt = min(self._queued, key=lambda q: (counts.get(q.client, 0),
                                                   self._last_start.get(q.client, 0), q.seq))
            self._queued.remove(nxt)
            self._last_start[nxt.client] = next(self._seq)
            thread = threading.Thread(target=self._run_one, args=(nxt.job_id, nxt.client),
                                      name=f"scengen-job-{nxt.job_id}", daemon=True)
            self._running[nxt.job_id] = (thread, nxt.client)
            thread.start()

    def _run_one(self, job_id: str, client: str) -> None:
        with self._lock:
            event = self._cancel.get(job_id, threading.Event())
        share = self.fair.share(client)
        try:
            if event.is_set() or self._stop.is_set():
                return
            kind = self._kind_of(job_id)
            if kind is not None:
                kind.run(job_id, event, self._stop, share)
                return
            with self.db.session() as s:
                if s.get(CatalogueRow, job_id) is None:
                    return
            try:
                self.runner.run(job_id, cancel=event, stop=self._stop, share=share,
                                only_active=True)
            except JobBusy as busy:
                self._run_elsewhere(job_id, client, busy)
                return
            with self._lock:
                self._elsewhere.pop(job_id, None)
        except Exception:  # keep the service alive whatever one job does
            log.exception("job %s crashed", job_id)
        finally:
            with self._lock:
                self._running.pop(job_id, None)
                self._cancel.pop(job_id, None)
                token = self._tokens.pop(job_id, None)
                self._dispatch()
            self.quotas.release(token)

    def _run_elsewhere(self, job_id: str, client: str, busy: JobBusy) -> None:
        """The job is run by another process (a CLI's ``catalogue create`` or ``resume``):
        leave it to it, and try again every ``ELSEWHERE_POLL`` s, so that a job whose
        process was killed before its end is finished here."""
        with self._lock:
            told = job_id in self._elsewhere
            self._elsewhere[job_id] = client
            if self._watcher is None:
                self._watcher = threading.Thread(target=self._watch_elsewhere,
                                                 name="scengen-jobs-elsewhere", daemon=True)
                self._watcher.start()
        if not told:
            log.info("catalogue %s is being run by another process (pid %s): left to it; "
                     "taken over here if that process ends before the job does",
                     job_id, busy.pid or "unknown")

    def _watch_elsewhere(self) -> None:
        while not self._stop.wait(ELSEWHERE_POLL):
            try:
                self._try_elsewhere()
            except Exception:  # the next round tries again
                log.exception("checking the jobs run by other processes failed")

    def _try_elsewhere(self) -> None:
        """Submit again each job another process held that is still unfinished (the
        runner takes it if it is free now); forget those that ended."""
        with self._lock:
            waiting = {j: c for j, c in self._elsewhere.items() if j not in self._running
                       and all(q.job_id != j for q in self._queued)}
        for job_id, client in waiting.items():
            with self.db.session() as s:
                row = s.get(CatalogueRow, job_id)
                status = None if row is None else row.status
            if status in repo.ACTIVE:
                self.submit(job_id, client=client)  # still busy: back in _elsewhere
                continue
            with self._lock:
                self._elsewhere.pop(job_id, None)
            log.info("catalogue %s: %s by the process that ran it", job_id,
                     status or "deleted")
