"""Engine, sessions and start-up migrations (programmatic ``alembic upgrade head``)."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import NullPool

log = logging.getLogger("scengen.db")

MIGRATIONS_DIR = Path(__file__).resolve().parent.parent / "migrations"


def _sqlite_pragmas(dbapi_connection: Any, connection_record: Any) -> None:
    # pysqlite's own transaction handling breaks savepoints (RELEASE of a savepoint it did
    # not BEGIN commits); SQLAlchemy's documented fix: no implicit transactions, and an
    # explicit BEGIN IMMEDIATE on every SQLAlchemy transaction (see _sqlite_begin).
    dbapi_connection.isolation_level = None
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.close()


#: execution option of the read-only engine (``Database.read_session``)
READ_ONLY = "scengen_read_only"


def _sqlite_begin(conn: Any) -> None:
    # Reads (``Database.read_session``): a deferred transaction, which under WAL reads a
    # snapshot and never waits for a writer. Everything else: IMMEDIATE, i.e. take the
    # write lock up front, so concurrent writers wait (busy timeout) instead of failing
    # when a read transaction would have to be upgraded.
    if conn.get_execution_options().get(READ_ONLY):
        conn.exec_driver_sql("BEGIN")
    else:
        conn.exec_driver_sql("BEGIN IMMEDIATE")


def make_engine(url: str) -> Engine:
    """An engine for ``url``. SQLite files get foreign keys, WAL and a busy timeout; their
    parent directory is created."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database and parsed.database != ":memory:":
            Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"timeout": 60})
        event.listen(engine, "connect", _sqlite_pragmas)
        event.listen(engine, "begin", _sqlite_begin)
        return engine
    return create_engine(url, pool_pre_ping=True)


def migrate(engine: Engine) -> None:
    """Bring the schema to the newest revision (idempotent)."""
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    # a throw-away engine without a pool: the migration's connection is closed at the end
    # and never joins the service's pool
    once = engine if engine.dialect.name == "sqlite" else create_engine(
        engine.url, poolclass=NullPool)
    try:
        with once.begin() as connection:
            cfg.attributes["connection"] = connection
            command.upgrade(cfg, "head")
    finally:
        if once is not engine:
            once.dispose()
    log.info("database schema at head (%s)", engine.url.render_as_string(hide_password=True))


class Database:
    """One engine and its session factory."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.engine = make_engine(url)
        self.sessions = sessionmaker(self.engine, expire_on_commit=False)
        #: the same pool; on SQLite its transactions are deferred (see _sqlite_begin)
        self.read_engine = self.engine.execution_options(**{READ_ONLY: True})
        self.read_sessions = sessionmaker(self.read_engine, expire_on_commit=False)
        self._probe: Engine | None = None

    def migrate(self) -> None:
        migrate(self.engine)

    def ping(self) -> None:
        """``select 1`` on a connection of its own (an engine without a pool, made once):
        the liveness probe never waits for a connection of the pool that the jobs and the
        requests share, however busy it is."""
        if self._probe is None:
            self._probe = create_engine(self.url, poolclass=NullPool)
        with self._probe.connect() as conn:
            conn.exec_driver_sql("select 1")

    @contextmanager
    def session(self) -> Iterator[Session]:
        """A session whose work is committed on success and rolled back on any error."""
        with self.sessions() as session, session.begin():
            yield session

    @contextmanager
    def read_session(self) -> Iterator[Session]:
        """A session that only reads. On SQLite it never waits for a writer (WAL snapshot,
        deferred transaction); a write in it may fail with "database is locked"."""
        with self.read_sessions() as session, session.begin():
            yield session

    def dispose(self) -> None:
        self.engine.dispose()
        if self._probe is not None:
            self._probe.dispose()
