"""Fixtures of the app tests (factories in tests/app/factories.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.app.factories import cli_store, pg_available, pg_database


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A fresh, empty database: a SQLite file, or a unique PostgreSQL database."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'store.db'}"
        return
    if not pg_available():
        pytest.fail("PostgreSQL is not reachable on 127.0.0.1:5432 "
                    "(run scripts/ensure-services.sh)")
    with pg_database() as url:
        yield url


@pytest.fixture(scope="session")
def shared_models() -> dict[str, Any]:
    """Model objects by their JSON, for the contexts of the tests that ask for them
    (``factories.share_models``): one per test process, so a model's memo is estimated
    once for all of them."""
    return {}


@pytest.fixture(scope="session")
def model_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data dir whose default model is fitted once per test process (then copied)."""
    from app.services.store import open_context
    from tests.app.factories import make_settings

    data_dir = tmp_path_factory.mktemp("model-cache")
    ctx = open_context(make_settings(data_dir))
    try:
        if ctx.startup_error:
            pytest.fail(f"the default model cannot be built: {ctx.startup_error}")
    finally:
        ctx.close()
    return data_dir


@pytest.fixture(scope="module")
def client(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """A TestClient on a private SQLite store (module-scoped: one app start per file)."""
    from fastapi.testclient import TestClient

    from tests.app.factories import copy_model_cache, make_app, make_settings

    data_dir = tmp_path_factory.mktemp("service")
    copy_model_cache(model_cache_dir, data_dir)
    app = make_app(make_settings(data_dir, sync_n_limit=50, upload_limit_bytes=1_000_000))
    with TestClient(app) as test_client:
        yield test_client


@pytest.fixture
def store(tmp_path: Path, model_cache_dir: Path,
          monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A private CLI store (SCENGEN_DATA_DIR) with the session's cached default model;
    yields its data directory."""
    data_dir = tmp_path / "data"
    with cli_store(data_dir, model_cache_dir, monkeypatch):
        yield data_dir
