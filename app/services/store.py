"""Opening the store: the context with the embedded dataset and its default model.

``open_context(settings)`` is what the service's lifespan and the CLI call:
``ServiceContext.open`` migrates the database, then ``register_defaults`` registers the
embedded TNO dataset and its default model (fitted by ``services.models.fit_model`` at the
first start and cached on disk under ``<data_dir>/models/`` keyed by the data's hash).
When the embedded data cannot be read or its model cannot be fitted, the context still
opens (health and stored catalogues answer) and ``ctx.startup_error`` says why.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

from app import domain
from app.atomic import atomic_path, write_atomic
from app.context import ServiceContext
from app.db import repository as repo
from app.db.models import DatasetRow, ModelRow
from app.errors import ServiceUnavailable
from app.services.models import fit_model, model_row
from app.settings import Settings
from sampler import CutInGMM

__all__ = ["EMBEDDED_ID", "EMBEDDED_NAME", "load_model", "open_context",
           "register_defaults"]

log = logging.getLogger("scengen.app")

EMBEDDED_ID = "tno-cutin"
EMBEDDED_NAME = ("TNO real cut-ins (2017, MIT): 208 usable of 297 recorded (89 partial or "
                 "implausible lane changes left out)")


def open_context(settings: Settings, *, load_defaults: bool = True) -> ServiceContext:
    """The store's context; with ``load_defaults`` the embedded dataset and default model
    (a failure is kept in ``ctx.startup_error``, not raised)."""
    ctx = ServiceContext.open(settings)
    if load_defaults:
        try:
            register_defaults(ctx)
        except (OSError, ValueError) as exc:
            # embedded data unreadable or its model cannot be fitted: the service still
            # answers (health, stored catalogues); the routes that need the model say why
            ctx.startup_error = str(exc)
            log.warning("embedded dataset/model not available: %s", exc)
    return ctx


def _embedded_table(ctx: ServiceContext) -> tuple[pd.DataFrame, str]:
    """The embedded parameter table, extracted once per data version into the store."""
    source = domain.embedded_source_hash()
    table_rel = f"datasets/{EMBEDDED_ID}/table-{source[:16]}.parquet"
    table_path = ctx.data_dir / table_rel
    if not table_path.exists():
        log.info("extracting the embedded TNO cut-ins (first start for this data)")
        fresh = domain.embedded_parameter_table()
        with atomic_path(table_path) as tmp:
            fresh.to_parquet(tmp, index=False)
    return pd.read_parquet(table_path), table_rel


def register_defaults(ctx: ServiceContext) -> None:
    """Register the embedded dataset and the default model (fit or load the cache)."""
    table, table_rel = _embedded_table(ctx)
    data_hash = domain.table_hash(table)
    with ctx.db.session() as s:
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
    ctx.default_dataset_id = EMBEDDED_ID

    options = dict(ctx.settings.default_model_options)
    key = data_hash[:16] + (f"-{domain.options_hash(options)[:8]}" if options else "")
    cache = ctx.data_dir / "models" / f"default-{key}.json"
    if cache.exists():
        log.info("loading the cached default model %s", cache)
        fitted = domain.describe_model(cache.read_text())
    else:
        log.info("first start for this data (hash %s): fitting the default model on "
                 "%d cut-ins (a few seconds; cached afterwards)", data_hash[:12], len(table))
        fitted = fit_model(table, options, source=EMBEDDED_ID)
        cache.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(cache, fitted.model_json.encode())
        log.info("fitted %d components; cached at %s", fitted.n_components, cache)
    model_id = f"default-{key[:12]}" + (key[16:] if options else "")
    with ctx.db.session() as s:
        for other in repo.list_models(s):
            if other.is_default and other.id != model_id:
                other.is_default = False
        existing = s.get(ModelRow, model_id)
        if existing is None:
            s.add(model_row(model_id, EMBEDDED_ID, fitted, options, is_default=True))
        else:
            existing.is_default = True
    ctx.remember_model(model_id, fitted.model)
    ctx.default_model_id = model_id


def load_model(ref: str | None, settings: Settings, field: str = "model") -> CutInGMM:
    """A model by reference: a model JSON file (a path ending in ``.json`` or an existing
    file), a model id of the store, or (None, '' or 'default') the store's default model
    (the store is opened for the lookup and closed again)."""
    if ref is not None and (ref.lower().endswith(".json") or Path(ref).is_file()):
        return CutInGMM.load(ref)
    ctx = open_context(settings, load_defaults=ref in (None, "", "default"))
    try:
        if ctx.startup_error:
            raise ServiceUnavailable(f"no default model: {ctx.startup_error}")
        return ctx.model(ctx.resolve_model_id(ref), field=field)
    finally:
        ctx.close()
