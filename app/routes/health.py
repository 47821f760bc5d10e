"""Liveness and versions."""

from __future__ import annotations

import anyio
import anyio.to_thread
from fastapi import APIRouter, Request
from pydantic import Field

from app.context import ServiceContext
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


#: the database probes of /health on other databases than SQLite run in threads of their
#: own: never queued behind the requests that fill Starlette's thread pool
_PROBES = anyio.CapacityLimiter(2)


@router.get("/health", response_model=Health,
            summary="Is the service up (and its database reachable)?")
async def health(request: Request) -> Health:
    """An async route (no thread of the shared pool) whose database probe has its own
    connection (``Database.ping``): neither the busy thread pool nor a pool of connections
    held by the jobs delays it (issue 27: /health p99 under the load test)."""
    ctx: ServiceContext = request.app.state.ctx
    if ctx.db.engine.dialect.name == "sqlite":
        ctx.db.ping()  # a local file: well under a millisecond
    else:
        await anyio.to_thread.run_sync(ctx.db.ping, limiter=_PROBES)
    return Health(status="warming" if ctx.warming else "ok", database=ctx.db.engine.dialect.name,
                  default_model=ctx.default_model_id, default_dataset=ctx.default_dataset_id,
                  executor="dask" if ctx.settings.dask_scheduler else "local",
                  startup_error=ctx.startup_error)


@router.get("/version", response_model=Versions,
            summary="Versions of scengen and its numerical libraries")
def version() -> Versions:
    return Versions(versions=versions())
