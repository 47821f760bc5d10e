"""FastAPI application factory. Routers are added per resource under app/routes/."""

from __future__ import annotations

from fastapi import FastAPI

from app import __version__


def create_app() -> FastAPI:
    application = FastAPI(title="scengen", version=__version__)

    @application.get("/health")
    def health() -> dict[str, str]:
        return {"status": "ok"}

    return application


app = create_app()
