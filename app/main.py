"""FastAPI application factory: settings, lifespan, error handlers, one router per resource.

The lifespan opens the ``ServiceContext`` once (database migrated to head, the embedded
TNO dataset and its default model — fitted at the first start and cached under the data
dir), starts the catalogue job thread (which resumes unfinished jobs) and closes all of it
at shutdown.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from app import __version__
from app.budget import BudgetGuard
from app.docs_offline import install_offline_docs
from app.errors import install_error_handlers
from app.guards import RequestGuards
from app.jobs.manager import JobKind, JobManager
from app.openapi_extras import install_openapi_extras
from app.routes import (
    catalogues,
    dashboard,
    datasets,
    health,
    models,
    risk,
    scenarios,
)
from app.routes import evaluations as evaluation_routes
from app.services import evaluations, store
from app.settings import Settings, get_settings

log = logging.getLogger("scengen.app")

#: routers in the order they appear in /docs; the dashboard (issue 6) adds its own here
ROUTERS = (
    health.router,
    datasets.router,
    models.router,
    scenarios.router,
    risk.router,
    catalogues.router,
    evaluation_routes.router,
    dashboard.router,
)


def _settings_of(app: FastAPI) -> Settings:
    """The app's settings: those given to ``create_app``, else ``get_settings()`` (which a
    test may override with ``app.dependency_overrides``)."""
    given = getattr(app.state, "settings", None)
    if isinstance(given, Settings):
        return given
    factory = app.dependency_overrides.get(get_settings, get_settings)
    settings: Settings = factory()
    return settings


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings = _settings_of(app)
    ctx = store.open_context(settings)
    jobs = JobManager(ctx.runner(), kinds={"eval": JobKind(
        run=evaluations.job(ctx), pending=lambda: evaluations.active_ids(ctx))},
        running_limit=settings.running_jobs_limit)
    jobs.start(resume=settings.resume_jobs)
    if settings.warm_start:
        ctx.warm_start()  # in the background: the first request need not wait
    app.state.ctx = ctx
    app.state.jobs = jobs
    log.info("scengen %s ready (database %s, default model %s)", __version__,
             ctx.db.engine.dialect.name, ctx.default_model_id)
    try:
        yield
    finally:
        jobs.stop()
        ctx.close()


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service. ``settings`` (default: ``get_settings()``, i.e. the ``SCENGEN_``
    environment) are read when the app starts; routes that depend on ``get_settings`` get
    the same object."""
    application = FastAPI(
        title="scengen",
        version=__version__,
        description="Risk-constrained cut-in scenarios: sample from a GMM learnt from real "
        "cut-ins, build concrete scenarios, score them with the Monte-Carlo TTR risk, and "
        "keep test catalogues. Errors: {\"error\": {\"status\", \"message\", \"field\"}}.",
        lifespan=lifespan,
        docs_url=None,  # self-hosted below: they work without internet
        redoc_url=None,
    )
    install_error_handlers(application)
    if settings is not None:
        application.state.settings = settings
        application.dependency_overrides[get_settings] = lambda: settings
    install_offline_docs(application)
    install_openapi_extras(application)

    application.add_middleware(BudgetGuard, settings=lambda: _settings_of(application))
    application.add_middleware(RequestGuards, settings=lambda: _settings_of(application))

    for router in ROUTERS:
        application.include_router(router)
    return application


app = create_app()
