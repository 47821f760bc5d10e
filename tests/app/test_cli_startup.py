"""Issue 25 item 7: ``scengen catalogue create|resume`` start the pool's workers before the
heavy imports and the store/model load, so that the two overlap."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from app.cli import main
from app.jobs.executors import InlineExecutor

ROOT = Path(__file__).resolve().parents[2]


class _Recording(InlineExecutor):
    def __init__(self, events: list[str]) -> None:
        super().__init__()
        self.events = events

    def warm(self) -> None:
        self.events.append("warm")

    def close(self) -> None:
        self.events.append("close")


@pytest.mark.parametrize("argv", [["catalogue", "create", "-n", "4", "-q"],
                                  ["catalogue", "resume", "cat-000000000000", "-q"]])
def test_the_pool_starts_before_the_store_opens_and_closes_when_it_fails(
        argv: list[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    import app.services.store as store

    events: list[str] = []
    monkeypatch.setattr("app.jobs.executors.make_executor",
                        lambda **_: _Recording(events))

    def open_context(settings: Any, *, load_defaults: bool = True) -> Any:
        events.append("open_context")  # where the store opens and the model loads
        raise PermissionError(13, "Permission denied", str(tmp_path / "scengen.db"))

    monkeypatch.setattr(store, "open_context", open_context)
    monkeypatch.setenv("SCENGEN_DATA_DIR", str(tmp_path))
    (tmp_path / "scengen.db").write_bytes(b"")  # resume needs a store to exist
    assert main(argv) == 2  # the user's error still ends as one line
    assert capsys.readouterr().err.strip() == (
        f"scengen: error: {tmp_path / 'scengen.db'}: permission denied")
    # the workers were started first, and not left running when the store failed
    assert events == ["warm", "open_context", "close"]


def test_the_pool_module_and_the_cli_import_no_sampler() -> None:
    """What runs before the pool starts imports neither the sampler, scikit-learn, numba
    nor riskcore (before: app.jobs.executors imported the chunk machinery, and the CLI's
    main() app.errors with FastAPI and riskcore: 2.4 s)."""
    code = ("import sys\n"
            "from app.cli import build_parser\n"
            "import app.jobs.executors, app.settings\n"
            "build_parser().parse_args(['catalogue', 'create', '-n', '4'])\n"
            "heavy = [m for m in ('sampler', 'sklearn', 'numba', 'riskcore', 'fastapi',"
            " 'app.jobs.chunk') if m in sys.modules]\n"
            "print(heavy)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == "[]"
