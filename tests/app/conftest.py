"""Fixtures of the app tests (factories in tests/app/factories.py)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.settings import get_settings
from tests.app.factories import TEST_MODEL_OPTIONS, copy_model_cache, pg_available, pg_database


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
    copy_model_cache(model_cache_dir, data_dir)
    monkeypatch.setenv("SCENGEN_DATA_DIR", str(data_dir))
    monkeypatch.setenv("SCENGEN_LOCAL_WORKERS", "0")
    monkeypatch.setenv("SCENGEN_WARM_START", "0")
    # as make_settings: a loaded test machine must not hit the CLI's time budget
    monkeypatch.setenv("SCENGEN_SYNC_BUDGET_SECONDS", "600")
    monkeypatch.setenv("SCENGEN_DEFAULT_MODEL_OPTIONS", json.dumps(TEST_MODEL_OPTIONS))
    monkeypatch.delenv("SCENGEN_DATABASE_URL", raising=False)
    monkeypatch.delenv("SCENGEN_DASK_SCHEDULER", raising=False)
    get_settings.cache_clear()
    yield data_dir
    get_settings.cache_clear()
