"""What the service and the CLI load once: database, embedded dataset, default model, jobs.

``ServiceContext.open(settings)`` migrates the database, registers the embedded TNO
dataset and its default model (fitted at the first start and cached on disk under
``<data_dir>/models/`` keyed by the data's hash), and builds the catalogue runner.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from app import domain, jsonconv
from app.cache import ViewCache
from app.db import repository as repo
from app.db.database import Database
from app.db.models import DatasetRow, ModelRow
from app.errors import ServiceUnavailable
from app.jobs.executors import ChunkExecutor, make_executor
from app.jobs.runner import CatalogueRunner
from app.schemas import DEFAULT_CONSTRAINTS
from app.settings import Settings

log = logging.getLogger("scengen.app")

EMBEDDED_ID = "tno-cutin"
EMBEDDED_NAME = ("TNO real cut-ins (2017, MIT): 208 usable of 297 recorded (89 partial or "
                 "implausible lane changes left out)")


@dataclass
class ServiceContext:
    settings: Settings
    db: Database
    data_dir: Path
    default_dataset_id: str | None = None
    default_model_id: str | None = None
    startup_error: str | None = None
    _executor: ChunkExecutor | None = None
    _models: dict[str, Any] = field(default_factory=dict)
    #: named caches of this context's users (dashboard views, status statistics)
    _caches: dict[str, ViewCache] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @classmethod
    def open(cls, settings: Settings, *, load_defaults: bool = True) -> ServiceContext:
        data_dir = Path(settings.data_dir).resolve()
        data_dir.mkdir(parents=True, exist_ok=True)
        log.info("data dir %s", data_dir)
        db = Database(settings.resolved_database_url)
        db.migrate()
        ctx = cls(settings=settings, db=db, data_dir=data_dir)
        if load_defaults:
            try:
                ctx.load_defaults()
            except (OSError, ValueError) as exc:
                # embedded data unreadable or its model cannot be fitted: the service still
                # answers (health, stored catalogues); the routes that need the model say why
                ctx.startup_error = str(exc)
                log.warning("embedded dataset/model not available: %s", exc)
        return ctx

    # ----------------------------------------------------------------- defaults
    def load_defaults(self) -> None:
        """Register the embedded dataset and the default model (fit or load the cache)."""
        source = domain.embedded_source_hash()
        table_rel = f"datasets/{EMBEDDED_ID}/table-{source[:16]}.parquet"
        table_path = self.data_dir / table_rel
        if not table_path.exists():
            log.info("extracting the embedded TNO cut-ins (first start for this data)")
            fresh = domain.embedded_parameter_table()
            table_path.parent.mkdir(parents=True, exist_ok=True)
            tmp = table_path.with_name(f".{table_path.name}.tmp")
            fresh.to_parquet(tmp, index=False)
            tmp.replace(table_path)
        table = pd.read_parquet(table_path)
        data_hash = domain.table_hash(table)
        with self.db.session() as s:
            row = s.get(DatasetRow, EMBEDDED_ID)
            if row is None:
                row = DatasetRow(id=EMBEDDED_ID, name=EMBEDDED_NAME, kind="embedded",
                                 embedded=True, data_hash=data_hash, n_cutins=len(table),
                                 table_path=table_rel,
                                 report={"source": "datasets.embedded (TNO cut-in.json, "
                                         "de Gelder et al. 2021)", "licence": "MIT",
                                         "provenance": "datasets/data/tno_cutin/PROVENANCE.md"})
                s.add(row)
            else:
                row.data_hash, row.n_cutins, row.table_path = data_hash, len(table), table_rel
        self.default_dataset_id = EMBEDDED_ID

        options = dict(self.settings.default_model_options)
        key = data_hash[:16] + (f"-{domain.options_hash(options)[:8]}" if options else "")
        cache = self.data_dir / "models" / f"default-{key}.json"
        if cache.exists():
            log.info("loading the cached default model %s", cache)
            fitted = domain.describe_model(cache.read_text())
        else:
            log.info("first start for this data (hash %s): fitting the default model on "
                     "%d cut-ins (a few seconds; cached afterwards)", data_hash[:12], len(table))
            fitted = domain.fit_model(table, options, source=EMBEDDED_ID)
            cache.parent.mkdir(parents=True, exist_ok=True)
            repo.write_file_atomic(cache, fitted.model_json.encode())
            log.info("fitted %d components; cached at %s", fitted.n_components, cache)
        model_id = f"default-{key[:12]}" + (key[16:] if options else "")
        with self.db.session() as s:
            for other in repo.list_models(s):
                if other.is_default and other.id != model_id:
                    other.is_default = False
            existing = s.get(ModelRow, model_id)
            if existing is None:
                s.add(self.model_row(model_id, EMBEDDED_ID, fitted, options, is_default=True))
            else:
                existing.is_default = True
        self._models[model_id] = fitted.model
        self.default_model_id = model_id

    @staticmethod
    def model_row(model_id: str, dataset_id: str, fitted: domain.FittedModel,
                  options: dict[str, Any], is_default: bool = False) -> ModelRow:
        return ModelRow(id=model_id, dataset_id=dataset_id, is_default=is_default,
                        options=jsonconv.encode(options), n_components=fitted.n_components,
                        model_hash=fitted.model_hash, model_json=fitted.model_json,
                        bic_curve=fitted.bic_curve, fit_report=fitted.fit_report)

    # ----------------------------------------------------------------- lookups
    def model(self, model_id: str, field: str = "body.model") -> Any:
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

    def runner(self) -> CatalogueRunner:
        return CatalogueRunner(self.db, self.data_dir, self.executor)

    def warm_start(self) -> threading.Thread:
        """In the background: start the executor's workers and load their kernels
        (``ChunkExecutor.warm``), and estimate what a first request with the default model
        and region would (P(B) and the model interval are memoised on the model object,
        ``sampler.model.memo``). Failures are logged only. Returns the thread of the latter."""
        self.executor.warm()

        def run() -> None:
            try:
                if self.default_model_id is None:
                    return
                model = self.model(self.default_model_id)
                domain.sample(model, domain.parse_constraints(DEFAULT_CONSTRAINTS), 1, 0)
            except Exception as exc:
                log.warning("warming the default model's region failed: %r", exc)

        thread = threading.Thread(target=run, name="scengen-warm-region", daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.close()
        self.db.dispose()
