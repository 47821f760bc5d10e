"""Point 3 of issue 5 for real: a `scengen catalogue create` process is SIGKILLed after some
chunks are stored; a new process resumes the job; the result equals an uninterrupted run —
against SQLite and against PostgreSQL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import func, select

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow, ChunkRow
from app.services import catalogues
from app.services.store import open_context
from tests.app.factories import copy_model_cache, make_settings, service_env, wait_for

ROOT = Path(__file__).resolve().parents[2]
N, CHUNK, SEED = 16, 2, 77


def _env(data_dir: Path, url: str) -> dict[str, str]:
    return service_env(data_dir, database_url=url, local_workers="1", chunk_size=str(CHUNK))


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "app.cli", "catalogue", *args]


def _chunks(db: Database) -> int:
    with db.session() as s:
        return int(s.scalar(select(func.count()).select_from(ChunkRow)) or 0)


@pytest.mark.slow
def test_killed_job_resumes_to_the_uninterrupted_result(database_url: str, tmp_path: Path,
                                                        model_cache_dir: Path) -> None:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    env = _env(data_dir, database_url)
    db = Database(database_url)
    db.migrate()  # so that the polling below can count chunks from the start
    log = tmp_path / "create.log"
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(
            _cli("create", "--n", str(N), "--seed", str(SEED), "--no-progress"), cwd=ROOT,
            env=env, stdout=log_file, stderr=log_file, start_new_session=True)
    db = Database(database_url)
    try:
        wait_for(lambda: _chunks(db) >= 2 or proc.poll() is not None, "two stored chunks")
        os.killpg(proc.pid, signal.SIGKILL)  # the process and its pool worker
    finally:
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, log.read_text()[-2000:]
    with db.session() as s:
        (row,) = s.scalars(select(CatalogueRow)).all()
        cid, status = row.id, row.status
        stored = repo.stored_chunk_indices(s, cid)
    assert status == "running"
    assert 2 <= len(stored) < N // CHUNK, "the kill came too late to test a resume"

    resumed = subprocess.run(_cli("resume", cid, "--no-progress"), cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    with db.session() as s:
        assert repo.get_catalogue(s, cid).status == "done"
        assert repo.count_scenarios(s, cid) == N
        chunks = repo.chunk_rows(s, cid)
    assert [c.chunk_index for c in chunks] == list(range(N // CHUNK))  # none lost or doubled
    db.dispose()

    # the uninterrupted run, in this process, on the same store
    ctx = open_context(make_settings(data_dir, database_url=database_url,
                                            chunk_size=CHUNK))
    try:
        clean = catalogues.create(ctx, n=N, seed=SEED, constraints=["ttc<3"])
        assert ctx.runner().run(clean.id) == "done"
        a = catalogues.export(ctx, cid, "jsonl", tmp_path / "resumed.jsonl")
        b = catalogues.export(ctx, clean.id, "jsonl", tmp_path / "clean.jsonl")
    finally:
        ctx.close()
    assert a.read_bytes() == b.read_bytes()
