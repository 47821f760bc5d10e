"""What the service and the CLI hold once: database, fitted models, executor, caches.

``ServiceContext.open(settings)`` migrates the database and builds the context; the
embedded dataset and its default model are registered by ``app.services.store``
(``open_context``, which the service's lifespan and the CLI call).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from app import domain
from app.cache import ViewCache
from app.db import repository as repo
from app.db.database import Database
from app.db.models import DatasetRow
from app.errors import ServiceUnavailable
from app.jobs.chunk import warm_worker
from app.jobs.executors import ChunkExecutor, make_executor
from app.jobs.runner import CatalogueRunner
from app.schemas import DEFAULT_CONSTRAINTS
from app.settings import Settings
from sampler import CutInGMM

log = logging.getLogger("scengen.app")

@dataclass
class ServiceContext:
    settings: Settings
    db: Database
    data_dir: Path
    default_dataset_id: str | None = None
    default_model_id: str | None = None
    startup_error: str | None = None
    _executor: ChunkExecutor | None = None
    #: what makes a campaign's runner from (SUT factory, simulator settings); None: the
    #: real one (``sampler.campaign.sut_runner``); tests put a stand-in here
    campaign_runner: Callable[[Any, dict[str, Any] | None], Any] | None = None
    _models: dict[str, CutInGMM] = field(default_factory=dict)
    #: named caches of this context's users (dashboard views, status statistics)
    _caches: dict[str, ViewCache] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    #: the start-up warm-up (``warm_start``) while it runs; /health says "warming" meanwhile
    _warm_thread: threading.Thread | None = None

    @classmethod
    def open(cls, settings: Settings) -> ServiceContext:
        """The store's context, its database migrated to head (nothing else loaded)."""
        data_dir = Path(settings.data_dir).resolve()
        data_dir.mkdir(parents=True, exist_ok=True)
        log.info("data dir %s", data_dir)
        db = Database(settings.resolved_database_url)
        db.migrate()
        return cls(settings=settings, db=db, data_dir=data_dir)

    # ----------------------------------------------------------------- lookups
    def model(self, model_id: str, field: str = "body.model") -> CutInGMM:
        """The fitted model object (cached in memory)."""
        with self._lock:
            if model_id in self._models:
                return self._models[model_id]
        with self.db.read_session() as s:
            text = repo.get_model(s, model_id, field=field).model_json
        model = domain.load_model(text)
        with self._lock:
            self._models[model_id] = model
        return model

    def remember_model(self, model_id: str, model: CutInGMM) -> None:
        """Keep a model just fitted or loaded, so ``model(model_id)`` need not read it."""
        with self._lock:
            self._models[model_id] = model

    def resolve_model_id(self, model_id: str | None) -> str:
        if model_id in (None, "", "default"):
            if self.default_model_id is None:
                raise ServiceUnavailable(
                    f"no default model: {self.startup_error or 'not loaded'}")
            return self.default_model_id
        assert model_id is not None
        return model_id

    def dataset_table(self, row: DatasetRow) -> pd.DataFrame:
        return pd.read_parquet(self.data_dir / row.table_path)

    def cache(self, name: str, size: int) -> ViewCache:
        """The named cache of this context (made at first use; it goes with the app)."""
        with self._lock:
            return self._caches.setdefault(name, ViewCache(size=size))

    # ----------------------------------------------------------------- jobs
    @property
    def executor(self) -> ChunkExecutor:
        with self._lock:
            if self._executor is None:
                self._executor = make_executor(dask_scheduler=self.settings.dask_scheduler,
                                               local_workers=self.settings.local_workers)
            return self._executor

    def adopt_executor(self, executor: ChunkExecutor) -> None:
        """Use ``executor`` (made from these settings with ``make_executor``, maybe started
        already) as this context's; the context closes it. The CLI starts the pool before
        it opens the store and loads the model, so that the two overlap (issue 25 item 7)."""
        with self._lock:
            if self._executor is not None:
                raise RuntimeError("this context has an executor already")
            self._executor = executor

    def runner(self) -> CatalogueRunner:
        return CatalogueRunner(self.db, self.data_dir, self.executor)

    def warm_start(self) -> threading.Thread:
        """In the background: start the executor's workers and load their kernels
        (``ChunkExecutor.warm``), load the same kernels in this process (a small
        ``POST /scenarios`` is scored here), and estimate what a first request with the
        default model and region would (P(B), the model interval and the data-support
        index are memoised on the model object, ``sampler.model.memo``). ``warming`` is
        true until all of it is done (/health: ``"status": "warming"``). Failures are
        logged only. Returns the thread."""

        def run() -> None:
            workers = self.executor.warm()
            try:
                warm_worker()
            except Exception as exc:
                log.warning("warming this process's kernels failed: %r", exc)
            try:
                if self.default_model_id is not None:
                    model = self.model(self.default_model_id)
                    domain.sample(model, domain.parse_constraints(DEFAULT_CONSTRAINTS), 1, 0)
            except Exception as exc:
                log.warning("warming the default model's region failed: %r", exc)
            if isinstance(workers, threading.Thread):
                workers.join()

        thread = threading.Thread(target=run, name="scengen-warm-start", daemon=True)
        with self._lock:
            self._warm_thread = thread
        thread.start()
        return thread

    @property
    def warming(self) -> bool:
        """True while the start-up warm-up (``warm_start``) runs."""
        thread = self._warm_thread
        return thread is not None and thread.is_alive()

    def close(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.close()
        self.db.dispose()
