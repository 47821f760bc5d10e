"""Data factories for the app tests: settings, stores, PostgreSQL databases, rows."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import psycopg
import pytest
from fastapi import FastAPI
from sqlalchemy.engine import make_url

from app.db import repository as repo
from app.db.database import Database
from app.main import create_app
from app.settings import Settings, get_settings

PG_ADMIN_URL = os.environ.get("SCENGEN_TEST_PG", "postgresql+psycopg://postgres@127.0.0.1:5432/test")


#: a quicker fit of the default model than the production options (same data, same code)
TEST_MODEL_OPTIONS: dict[str, Any] = {"n_init": 1, "cv_folds": 2, "n_report_samples": 2000,
                                      "k_range": [1, 4]}


def make_settings(data_dir: Path, **overrides: Any) -> Settings:
    """Settings for a private store under ``data_dir`` (SQLite unless database_url given)."""
    values: dict[str, Any] = {"data_dir": data_dir, "local_workers": 0, "chunk_size": 5,
                              "default_model_options": TEST_MODEL_OPTIONS,
                              "warm_start": False,
                              # a loaded test machine must not turn slow requests into
                              # 422s; the budget has its own tests (test_budget.py)
                              "sync_budget_seconds": 600.0,
                              # TestClient's requests carry Host: testserver
                              "trusted_hosts": ["localhost", "127.0.0.1", "::1",
                                                "testserver"]}
    values.update(overrides)
    return Settings(**values)


def make_app(settings: Settings) -> FastAPI:
    """The service app with these settings."""
    return create_app(settings)


def wait_for(predicate: Callable[[], bool], what: str, attempts: int = 600,
             pause: float = 0.1) -> None:
    """Poll ``predicate`` (bounded number of attempts; no wall-clock assertions)."""
    for _ in range(attempts):
        if predicate():
            return
        time.sleep(pause)
    raise AssertionError(f"gave up waiting for {what}")


def pg_available() -> bool:
    try:
        with psycopg.connect(_libpq(PG_ADMIN_URL), connect_timeout=3):
            return True
    except psycopg.Error:
        return False


def _libpq(url: str) -> str:
    u = make_url(url)
    return u.set(drivername="postgresql").render_as_string(hide_password=False)


@contextmanager
def pg_database() -> Iterator[str]:
    """A fresh, uniquely named PostgreSQL database; dropped afterwards. Yields its URL."""
    name = f"scengen_t_{uuid.uuid4().hex[:16]}"
    admin = _libpq(PG_ADMIN_URL)
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    try:
        yield make_url(PG_ADMIN_URL).set(database=name).render_as_string(hide_password=False)
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


#: the time budget of test services and CLI runs (SCENGEN_SYNC_BUDGET_SECONDS): a loaded
#: test machine must not turn slow requests into 422s; tests about the budget set their own
GENEROUS_BUDGET = "600"


def service_env(data_dir: Path, **settings: str) -> dict[str, str]:
    """Environment of a service/CLI subprocess on the store in ``data_dir``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SCENGEN_")}
    env["SCENGEN_DATA_DIR"] = str(data_dir)
    env["SCENGEN_DEFAULT_MODEL_OPTIONS"] = json.dumps(TEST_MODEL_OPTIONS)
    env["SCENGEN_SYNC_BUDGET_SECONDS"] = GENEROUS_BUDGET  # as make_settings
    env.update({f"SCENGEN_{k.upper()}": v for k, v in settings.items()})
    return env


def share_models(monkeypatch: pytest.MonkeyPatch, kept: dict[str, Any]) -> None:
    """Every context opened from now on (until ``monkeypatch`` undoes it) keeps the one
    model object ``kept`` holds for a model's JSON, the first one registered, instead of
    its own copy: as one service process keeps its model between requests. Its memo
    (``sampler.model.memo``: the campaign proposal's fixed parts, P(B) and its bootstrap,
    about 9 s per model object, from a fixed seed) is then estimated once, not once per
    CLI call. Not for a test that checks a fresh model gives the same bytes."""
    from app.context import ServiceContext

    remember = ServiceContext.remember_model

    def keep(self: ServiceContext, model_id: str, model: Any) -> None:
        remember(self, model_id, kept.setdefault(model.to_json(), model))

    monkeypatch.setattr(ServiceContext, "remember_model", keep)


def copy_model_cache(src_data_dir: Path, dst_data_dir: Path) -> None:
    """Reuse the extracted embedded table and the fitted default model (both caches are
    keyed by the data's hash)."""
    for sub in ("models", "datasets"):
        src = src_data_dir / sub
        if src.is_dir():
            shutil.copytree(src, dst_data_dir / sub, dirs_exist_ok=True)


def scenario_rows(chunk_index: int, start: int, count: int) -> list[dict[str, Any]]:
    """Stored-scenario rows as a chunk would produce them (hand-made numbers)."""
    rows = []
    for k in range(count):
        idx = start + k
        rows.append({
            "idx": idx, "chunk_index": chunk_index,
            "params": {"gap": 10.0 + idx, "dv": 5.0},
            "ttc": (10.0 + idx) / 5.0 if idx % 4 else float("inf"),
            "risk": idx / 100.0,
            "exposure_weight": 1.0,
            "summary": {"risk": idx / 100.0, "min_ttr": "Infinity"},
        })
    return rows


ROOT = Path(__file__).resolve().parents[2]


@contextmanager
def process_service(cmd: list[str], env: dict[str, str], log: Path, port: int,
                    name: str) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """The HTTP service ``cmd`` (listening on loopback ``port``) in its own session with
    ``env``; yields (the process, its base URL) once /health answers (bounded polling),
    then stops its whole session (SIGTERM, SIGKILL after 60 s; nothing to do when a test
    killed it already). Its output goes to ``log``; ``name`` names it in failures."""
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log_file, stderr=log_file,
                                start_new_session=True)
    base = f"http://127.0.0.1:{port}"

    def up() -> bool:
        if proc.poll() is not None:
            raise AssertionError(f"{name} exited: {log.read_text()[-2000:]}")
        try:
            return httpx.get(f"{base}/health", timeout=2).status_code == 200
        except httpx.TransportError:
            return False

    try:
        wait_for(up, f"{name} to answer /health", attempts=1200)
        yield proc, base
    finally:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=60)
        except ProcessLookupError:
            pass
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)


def serve_cmd(port: int) -> list[str]:
    """The command line of ``scengen serve`` on loopback ``port`` (this interpreter)."""
    return [sys.executable, "-m", "app.cli", "serve", "--port", str(port)]


@contextmanager
def serve_service(env: dict[str, str], log: Path
                  ) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """A ``scengen serve`` on a free loopback port with ``env`` (``process_service``);
    yields (the process, its base URL) once /health answers, then stops its whole session
    (a SIGKILLed one may leave its pool worker for a moment)."""
    port = free_port()
    with process_service(serve_cmd(port), env, log, port, "scengen serve") as out:
        yield out


def _store_db(data_dir: Path) -> Database:
    return Database(f"sqlite:///{data_dir / 'scengen.db'}")


def status_in_store(data_dir: Path, cid: str) -> str:
    """Catalogue ``cid``'s status as the SQLite store in ``data_dir`` holds it now (read
    through a database handle of its own, beside whichever process runs the job)."""
    db = _store_db(data_dir)
    try:
        with db.session() as s:
            return repo.get_catalogue(s, cid).status
    finally:
        db.dispose()


def chunk_indices_in_store(data_dir: Path, cid: str) -> list[int]:
    """The indices of catalogue ``cid``'s chunks stored in the SQLite store in
    ``data_dir``, in the store's order (``repository.chunk_rows``): a chunk stored twice
    appears twice."""
    db = _store_db(data_dir)
    try:
        with db.session() as s:
            return [c.chunk_index for c in repo.chunk_rows(s, cid)]
    finally:
        db.dispose()


@contextmanager
def uvicorn_service(env: dict[str, str], log: Path, *args: str) -> Iterator[str]:
    """``uvicorn app.main:app`` on a free loopback port with ``env`` (``process_service``);
    yields its base URL. Without SCENGEN_SYNC_BUDGET_SECONDS in ``env`` the service gets
    ``GENEROUS_BUDGET``."""
    env = {"SCENGEN_SYNC_BUDGET_SECONDS": GENEROUS_BUDGET, **env}
    port = free_port()
    cmd = [sys.executable, "-m", "uvicorn", "app.main:app", "--host", "127.0.0.1",
           "--port", str(port), *args]
    with process_service(cmd, env, log, port, "uvicorn") as (_, base):
        yield base


@contextmanager
def cli_store(data_dir: Path, model_cache_dir: Path,
              monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The environment of ``store`` on ``data_dir`` (also for module-scoped fixtures, with
    a ``pytest.MonkeyPatch.context()``)."""
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
    try:
        yield
    finally:
        get_settings.cache_clear()
