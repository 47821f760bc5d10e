"""Issue 25 item 7: ``scengen catalogue create|resume`` start the pool's workers before the
heavy imports and the store/model load, so that the two overlap."""

from __future__ import annotations

import os
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


def test_evaluate_help_imports_no_sampler() -> None:
    """``scengen evaluate --help`` prints the stop rule's default from the CLI's written-out
    copy (app.cli.evaluate.DEFAULT_RHW), not by loading the sampler to read it (a help
    formatter that did: 2.1 s instead of 0.06 s)."""
    code = ("import contextlib, io, sys\n"
            "from app.cli import build_parser\n"
            "out = io.StringIO()\n"
            "with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):\n"
            "    build_parser().parse_args(['evaluate', '--help'])\n"
            "assert '--rhw' in out.getvalue(), out.getvalue()\n"
            "heavy = [m for m in ('sampler', 'sklearn', 'numba', 'riskcore', 'fastapi')"
            " if m in sys.modules]\n"
            "print(heavy)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == "[]"


class _Noted:
    """Writes ``path`` when it is destroyed, e.g. in the interpreter's module teardown."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __del__(self, _open: Any = open) -> None:
        with _open(self.path, "w") as f:
            f.write("torn down")


_KEPT: list[_Noted] = []


def keep_until_teardown(path: str) -> int:
    """A pool task (for the test only): leave an object to the worker's teardown."""
    _KEPT.append(_Noted(path))
    return os.getpid()


def test_pool_workers_end_without_the_interpreter_teardown(tmp_path: Path) -> None:
    """The local pool's workers skip the module teardown at a clean shutdown (0.3 s each
    that ``shutdown(wait=True)`` waited for); the plain lifeline initializer, the control,
    shows the teardown is what the object's file records. Either way no worker is left."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import psutil  # type: ignore[import-untyped]

    from app.jobs.lifeline import die_with_parent, quick_exit_worker

    for initializer, torn_down in ((die_with_parent, True), (quick_exit_worker, False)):
        marker = tmp_path / f"{initializer.__name__}.txt"
        pool = ProcessPoolExecutor(max_workers=1,
                                   mp_context=multiprocessing.get_context("spawn"),
                                   initializer=initializer, initargs=(os.getpid(),))
        pid = pool.submit(keep_until_teardown, str(marker)).result()
        pool.shutdown(wait=True)
        assert marker.exists() is torn_down, initializer.__name__
        assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == "zombie"
