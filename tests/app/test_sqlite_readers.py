"""Issue 14 item 14: on SQLite, reads (and /health) do not wait for a writer (WAL snapshot,
deferred read transactions); writers still take the write lock up front."""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy import text
from sqlalchemy.engine import make_url

from app.db.database import Database
from app.db.models import CatalogueRow


@contextmanager
def write_lock(db_file: str) -> Iterator[None]:
    """Another process's writer holding SQLite's write lock until the block ends."""
    other = sqlite3.connect(db_file, timeout=0, isolation_level=None)
    try:
        other.execute("BEGIN IMMEDIATE")
        other.execute("CREATE TABLE IF NOT EXISTS _lock_probe (x INTEGER)")
        yield
        other.execute("ROLLBACK")
    finally:
        other.close()


def finishes_while_locked(db_file: str, work: Callable[[], Any],
                          patience: float = 15.0) -> tuple[bool, Any]:
    """Run ``work`` in a thread while another connection holds the write lock; whether it
    finished before the lock was released (bounded wait) and its result."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = work()
        except Exception as exc:  # surfaced through the result
            box["value"] = exc

    with write_lock(db_file):
        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        thread.join(timeout=patience)
        finished = not thread.is_alive()
    thread.join(timeout=120)
    return finished, box.get("value")


def test_journal_is_wal_and_a_read_session_does_not_wait_for_a_writer(tmp_path: Path) -> None:
    db = Database(f"sqlite:///{tmp_path / 's.db'}")
    try:
        db.migrate()
        with db.read_session() as s:
            assert s.execute(text("PRAGMA journal_mode")).scalar() == "wal"

        def read() -> int:
            with db.read_session() as s:
                return len(list(s.query(CatalogueRow)))

        finished, value = finishes_while_locked(str(tmp_path / "s.db"), read)
        assert finished and value == 0

        def write() -> str:
            with db.session() as s:
                s.execute(text("CREATE TABLE IF NOT EXISTS _w (x INTEGER)"))
            return "written"

        # a writer waits for the lock (busy timeout) and then succeeds
        finished, value = finishes_while_locked(str(tmp_path / "s.db"), write, patience=1.0)
        assert not finished and value == "written"
    finally:
        db.dispose()


def test_health_and_listing_answer_while_a_writer_holds_the_lock(client: Any) -> None:
    db_file = make_url(client.app.state.ctx.db.url).database
    for path in ("/health", "/catalogues", "/datasets", "/models"):
        finished, response = finishes_while_locked(db_file, lambda p=path: client.get(p))
        assert finished, f"{path} waited for the writer"
        assert response.status_code == 200, (path, response)
