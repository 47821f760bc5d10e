"""Liveness and versions."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from sqlalchemy import text

from app.deps import ContextDep
from app.versions import versions

router = APIRouter(tags=["service"])


@router.get("/health", summary="Is the service up (and its database reachable)?")
def health(ctx: ContextDep) -> dict[str, Any]:
    with ctx.db.engine.connect() as conn:
        conn.execute(text("select 1"))
    return {
        "status": "ok",
        "database": ctx.db.engine.dialect.name,
        "default_model": ctx.default_model_id,
        "default_dataset": ctx.default_dataset_id,
        "executor": "dask" if ctx.settings.dask_scheduler else "local",
        "startup_error": ctx.startup_error,
    }


@router.get("/version", summary="Versions of scengen and its numerical libraries")
def version() -> dict[str, Any]:
    return {"versions": versions()}
