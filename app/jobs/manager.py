"""The service's job queue: one background thread runs jobs one at a time (each job
already uses every worker of the executor): catalogues (``CatalogueRunner``) and the other
kinds given as ``kinds`` (id prefix -> ``JobKind``: how to run one, which to resume), e.g.
the evaluations of ``app.services.evaluations``."""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow
from app.jobs.runner import CatalogueRunner
from app.quotas import ClientQuotas, QuotaToken

log = logging.getLogger("scengen.jobs")


@dataclass(frozen=True)
class JobKind:
    """A kind of job besides catalogues: ``run(id, cancel, stop)`` -> final status, and
    ``pending()`` -> the ids to resume at start."""

    run: Callable[[str, threading.Event, threading.Event], str]
    pending: Callable[[], list[str]]


class JobManager:
    def __init__(self, runner: CatalogueRunner,
                 kinds: Mapping[str, JobKind] | None = None) -> None:
        self.runner = runner
        self.kinds = dict(kinds or {})
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._cancel: dict[str, threading.Event] = {}
        #: per-client quotas of every job kind (``app.quotas``), released as jobs end
        self.quotas = ClientQuotas()
        self._tokens: dict[str, QuotaToken] = {}
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def db(self) -> Database:
        return self.runner.db

    def start(self, resume: bool = True) -> None:
        self._thread = threading.Thread(target=self._loop, name="scengen-jobs", daemon=True)
        self._thread.start()
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

    def submit(self, catalogue_id: str, quota: QuotaToken | None = None) -> None:
        """Queue a job; ``quota`` (from ``self.quotas``) is released when it ends."""
        with self._lock:
            self._cancel[catalogue_id] = threading.Event()
            if quota is not None:
                self._tokens[catalogue_id] = quota
        self._queue.put(catalogue_id)

    def cancel(self, catalogue_id: str) -> None:
        with self._lock:
            event = self._cancel.get(catalogue_id)
        if event is not None:
            event.set()

    def stop(self) -> None:
        """Stop after the chunks in flight; unfinished jobs stay resumable."""
        self._stop.set()
        self._queue.put(None)
        if self._thread is not None:
            self._thread.join(timeout=60)
        # the executor belongs to the ServiceContext, which closes it

    def _kind_of(self, job_id: str) -> JobKind | None:
        prefix = job_id.partition("-")[0]
        return self.kinds.get(prefix)

    def _loop(self) -> None:
        while True:
            cid = self._queue.get()
            if cid is None or self._stop.is_set():
                return
            with self._lock:
                event = self._cancel.get(cid, threading.Event())
            try:
                if event.is_set():
                    continue
                kind = self._kind_of(cid)
                if kind is not None:
                    kind.run(cid, event, self._stop)
                    continue
                with self.db.session() as s:
                    if s.get(CatalogueRow, cid) is None:
                        continue
                self.runner.run(cid, cancel=event, stop=self._stop)
            except Exception:  # keep the loop alive whatever one job does
                log.exception("job %s crashed", cid)
            finally:
                with self._lock:
                    self._cancel.pop(cid, None)
                    token = self._tokens.pop(cid, None)
                self.quotas.release(token)
