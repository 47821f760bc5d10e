"""The service's job queue: one background thread runs catalogue jobs one at a time
(each job already uses every worker of the executor)."""

from __future__ import annotations

import logging
import queue
import threading

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow
from app.jobs.runner import CatalogueRunner

log = logging.getLogger("scengen.jobs")


class JobManager:
    def __init__(self, runner: CatalogueRunner) -> None:
        self.runner = runner
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._cancel: dict[str, threading.Event] = {}
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

    def submit(self, catalogue_id: str) -> None:
        with self._lock:
            self._cancel[catalogue_id] = threading.Event()
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
                with self.db.session() as s:
                    if s.get(CatalogueRow, cid) is None:
                        continue
                self.runner.run(cid, cancel=event, stop=self._stop)
            except Exception:  # keep the loop alive whatever one job does
                log.exception("job %s crashed", cid)
            finally:
                with self._lock:
                    self._cancel.pop(cid, None)
