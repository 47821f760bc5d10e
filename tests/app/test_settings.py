"""Settings come from SCENGEN_* variables; the database defaults to a file in the data dir."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from app.settings import Settings


def test_environment_variables_with_the_prefix(monkeypatch: pytest.MonkeyPatch,
                                               tmp_path: Path) -> None:
    monkeypatch.setenv("SCENGEN_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("SCENGEN_DASK_SCHEDULER", "tcp://scheduler:8786")
    monkeypatch.setenv("SCENGEN_SYNC_N_LIMIT", "42")
    s = Settings()
    assert s.data_dir == tmp_path
    assert s.dask_scheduler == "tcp://scheduler:8786"
    assert s.sync_n_limit == 42
    assert s.resolved_database_url == f"sqlite:///{(tmp_path / 'scengen.db').resolve()}"
    monkeypatch.setenv("SCENGEN_DATABASE_URL", "postgresql+psycopg://u@h/db")
    assert Settings().resolved_database_url == "postgresql+psycopg://u@h/db"


def test_bad_values_are_refused_naming_the_setting(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SCENGEN_CHUNK_SIZE", "0")
    with pytest.raises(ValidationError, match="chunk_size"):
        Settings()
