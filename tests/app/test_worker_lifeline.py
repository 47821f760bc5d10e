"""Issue 14 item 15: a SIGKILLed parent leaves no pool worker (nor resource tracker)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest

from tests.app.factories import wait_for

ROOT = Path(__file__).resolve().parents[2]


def sleepy_chunk(spec: object, index: int) -> object:
    """A chunk function that announces its worker and then blocks (for the test only)."""
    folder = Path(os.environ["LIFELINE_DIR"])
    (folder / f"worker-{os.getpid()}").write_text(str(index))
    time.sleep(300)
    return None


PARENT = textwrap.dedent("""
    import sys, time
    from app.jobs.executors import LocalPoolExecutor
    from tests.app.test_worker_lifeline import sleepy_chunk

    ex = LocalPoolExecutor(2, fn=sleepy_chunk)
    for _ in ex.run(None, range(4)):
        pass
""")


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _sigkill_and_wait_for_orphans(parent: subprocess.Popen[bytes],
                                  children: list[psutil.Process]) -> None:
    """SIGKILL ``parent``; then poll (bounded) until none of ``children`` is left."""
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait(timeout=30)
    wait_for(lambda: not any(_alive(c.pid) for c in children),
             "the pool workers to die with their parent", attempts=200)


def _reap(parent: subprocess.Popen[bytes], children: list[psutil.Process]) -> None:
    """Clean up what this test started, whatever happened."""
    if parent.poll() is None:
        parent.kill()
        parent.wait(timeout=30)
    for child in children:
        if _alive(child.pid):
            child.kill()


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux process tree")
def test_pool_workers_and_tracker_die_with_a_sigkilled_parent(tmp_path: Path) -> None:
    env = {**os.environ, "LIFELINE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    parent = subprocess.Popen([sys.executable, "-c", PARENT], cwd=ROOT, env=env)
    children: list[psutil.Process] = []
    try:
        wait_for(lambda: len(list(tmp_path.glob("worker-*"))) == 2, "two busy workers",
                 attempts=1200)
        children = psutil.Process(parent.pid).children(recursive=True)
        workers = {int(p.name.split("-")[1]) for p in tmp_path.glob("worker-*")}
        assert workers <= {c.pid for c in children}
        assert len(children) >= 3  # two workers and the resource tracker
        _sigkill_and_wait_for_orphans(parent, children)
    finally:
        _reap(parent, children)


@pytest.mark.slow
def test_initializer_ends_a_worker_whose_parent_is_gone() -> None:
    from app.jobs import lifeline

    # the parent pid the worker was started by is not its parent: it ends at once
    code = ("import os; from app.jobs.lifeline import die_with_parent; "
            "die_with_parent(os.getppid() + 100000); print('survived')")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 1 and "survived" not in done.stdout
    assert lifeline.PR_SET_PDEATHSIG == 1


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux process tree")
def test_cli_scoring_workers_die_with_a_sigkilled_cli(store: Path, tmp_path: Path) -> None:
    """Issue 14 item 15: ``scengen sample --score --workers 2`` SIGKILLed mid-run leaves no
    scoring worker behind (sampler.scenario.scoring's pool has the lifeline initializer)."""
    out = tmp_path / "out.jsonl"
    cli = [sys.executable, "-c", "import sys; from app.cli import main; sys.exit(main())",
           "sample", "-n", "5000", "--seed", "3", "--score", "--workers", "2", "-q",
           "-o", str(out)]
    parent = subprocess.Popen(cli, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    children: list[psutil.Process] = []

    def workers_started() -> bool:
        nonlocal children
        children = [c for c in psutil.Process(parent.pid).children(recursive=True)
                    if _alive(c.pid)]
        return len(children) >= 2

    try:
        wait_for(workers_started, "two scoring workers", attempts=1800)
        _sigkill_and_wait_for_orphans(parent, children)
        assert not out.exists() or out.stat().st_size == 0  # killed before writing
    finally:
        _reap(parent, children)


@pytest.mark.parametrize(("args", "fragment"), [((0,), "n_workers"), ((1.5,), "n_workers"),
                                                ((2, "nope"), "mp_context")])
def test_lifeline_pool_refuses_bad_arguments(args: tuple[object, ...], fragment: str) -> None:
    from app.jobs.lifeline import lifeline_pool

    with pytest.raises(ValueError, match=fragment), lifeline_pool(*args):  # type: ignore[arg-type]
        pass


def test_lifeline_pool_of_one_runs_in_this_process() -> None:
    from app.jobs.lifeline import lifeline_pool

    with lifeline_pool(1) as pool:
        assert pool is None
