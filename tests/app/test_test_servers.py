"""Every test service and CLI subprocess gets a generous time budget (a loaded machine
turned the 10 s default of SCENGEN_SYNC_BUDGET_SECONDS into 422s in the browser tests);
a test that sets its own budget keeps it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.app import factories


def test_service_env_gives_a_generous_budget_unless_told(tmp_path: Path) -> None:
    assert factories.service_env(tmp_path)["SCENGEN_SYNC_BUDGET_SECONDS"] == "600"
    own = factories.service_env(tmp_path, sync_budget_seconds="10")
    assert own["SCENGEN_SYNC_BUDGET_SECONDS"] == "10"


class _Started(Exception):
    pass


@pytest.mark.parametrize(("given", "expected"), [(None, "600"), ("2.5", "2.5")])
def test_uvicorn_service_starts_with_a_generous_budget_unless_told(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, given: str | None,
        expected: str) -> None:
    seen: dict[str, str] = {}

    def popen(cmd: list[str], **kw: Any) -> None:
        seen.update(kw["env"])
        raise _Started

    monkeypatch.setattr(factories.subprocess, "Popen", popen)
    env = {"SCENGEN_DATA_DIR": str(tmp_path)}  # as the browser tests build theirs
    if given is not None:
        env["SCENGEN_SYNC_BUDGET_SECONDS"] = given
    with pytest.raises(_Started), factories.uvicorn_service(env, tmp_path / "log"):
        pass
    assert seen["SCENGEN_SYNC_BUDGET_SECONDS"] == expected
    assert seen["SCENGEN_DATA_DIR"] == str(tmp_path)
