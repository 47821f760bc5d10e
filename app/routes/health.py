"""Liveness and versions."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import Field
from sqlalchemy import text

from app.deps import ContextDep
from app.schemas import ApiModel
from app.versions import versions

router = APIRouter(tags=["service"])


class Health(ApiModel):
    status: str = Field(description="ok: ready; warming: up, but still loading what the "
                        "first scored request needs (the workers' compiled kernels, the "
                        "default model's region estimate), which a request sent now waits for")
    database: str = Field(description="sqlite | postgresql")
    default_model: str | None
    default_dataset: str | None
    executor: str = Field(description="local | dask")
    startup_error: str | None = Field(description="why the default model is missing")


class Versions(ApiModel):
    versions: dict[str, str | None] = Field(description="package -> version (null: absent)")


@router.get("/health", response_model=Health,
            summary="Is the service up (and its database reachable)?")
def health(ctx: ContextDep) -> Health:
    with ctx.db.read_engine.connect() as conn:
        conn.execute(text("select 1"))
    return Health(status="warming" if ctx.warming else "ok", database=ctx.db.engine.dialect.name,
                  default_model=ctx.default_model_id, default_dataset=ctx.default_dataset_id,
                  executor="dask" if ctx.settings.dask_scheduler else "local",
                  startup_error=ctx.startup_error)


@router.get("/version", response_model=Versions,
            summary="Versions of scengen and its numerical libraries")
def version() -> Versions:
    return Versions(versions=versions())
