"""One runner per catalogue job, across processes: whoever runs a job (a service's job
manager, the CLI's ``catalogue create`` or ``resume``) holds its lock file in the store.
``catalogue resume`` of a job a service runs used to run it a second time beside the
service; a service started while ``catalogue create`` ran resumed that job as well. Now the
second runner leaves the job to the first (the CLI exits 2 naming the holder's pid; the
service waits and takes the job over only if its holder ends before the job does)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from sqlalchemy.exc import OperationalError

from app.db import repository as repo
from app.db.database import Database
from app.jobs import joblock
from app.services import catalogues
from app.services.store import open_context
from tests.app.factories import (
    chunk_indices_in_store,
    copy_model_cache,
    make_settings,
    serve_service,
    service_env,
    status_in_store,
    wait_for,
)

ROOT = Path(__file__).resolve().parents[2]
N, CHUNK = 40, 2
RUNNING = "chunks stored, running the rest"


def _pool_workers(pid: int) -> list[int]:
    """The pool workers (spawned processes) whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (entry / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and b"spawn_main" in cmd:
            found.append(int(entry.name))
    return found


def _workers_of(pid: int) -> list[int]:
    found: list[int] = []
    wait_for(lambda: bool(found.extend(_pool_workers(pid)) or found),
             f"the pool worker of {pid}", attempts=1200)
    return found


def _lock_file(data_dir: Path, cid: str) -> Path:
    return data_dir / "jobs" / f"{cid}.lock"


def _catalogues(data_dir: Path) -> list[tuple[str, str]]:
    db = Database(f"sqlite:///{data_dir / 'scengen.db'}")
    try:
        with db.session() as s:
            return [(r.id, r.status) for r in repo.list_catalogues(s)]
    finally:
        db.dispose()


def _signal_all(pids: list[int], sig: signal.Signals) -> None:
    for pid in pids:
        os.kill(pid, sig)


def _left(log: Path, line: str) -> bool:
    """Whether the service's log says it left the job to the CLI; a failure as soon as
    it says it runs the job itself."""
    text = log.read_text()
    assert RUNNING not in text, f"the service runs the CLI's job: {text[-2000:]}"
    return line in text


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "app.cli", "catalogue", *args, "-q"]


@pytest.fixture
def store(tmp_path: Path, model_cache_dir: Path) -> tuple[Path, dict[str, str]]:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    return data_dir, service_env(data_dir, local_workers="1", warm_start="0")


def test_the_job_lock_names_its_holder_and_leaves_nothing(tmp_path: Path) -> None:
    held = joblock.acquire(tmp_path, "cat-1")
    try:
        assert _lock_file(tmp_path, "cat-1").read_text() == f"{os.getpid()}\n"
        with pytest.raises(joblock.JobBusy) as busy:
            joblock.acquire(tmp_path, "cat-1")  # another open file: refused, even here
        assert busy.value.pid == os.getpid()
        joblock.release(joblock.acquire(tmp_path, "cat-2"))  # a job of its own is free
        assert not os.get_inheritable(held.fd)  # spawned workers never hold it
    finally:
        joblock.release(held)
    assert list((tmp_path / "jobs").iterdir()) == []
    joblock.release(joblock.acquire(tmp_path, "cat-1"))


def test_the_check_names_the_holder_and_takes_or_makes_nothing(tmp_path: Path) -> None:
    joblock.check_free(tmp_path, "cat-1")
    assert list(tmp_path.iterdir()) == []  # no lock file, no folder: no holder
    held = joblock.acquire(tmp_path, "cat-1")
    try:
        with pytest.raises(joblock.JobBusy) as busy:
            joblock.check_free(tmp_path, "cat-1")
        assert busy.value.pid == os.getpid()
        with pytest.raises(joblock.JobBusy):  # still held after the check
            joblock.acquire(tmp_path, "cat-1")
        joblock.check_free(tmp_path, "cat-2")
        for not_a_name in ("", "../jobs/cat-1", "cat-1/", "cat\0"):
            joblock.check_free(tmp_path, not_a_name)
    finally:
        joblock.release(held)
    # a lock file its holder left (SIGKILL) is no holder; the check leaves it unlocked
    _lock_file(tmp_path, "cat-1").write_text("4242\n")
    joblock.check_free(tmp_path, "cat-1")
    joblock.release(joblock.acquire(tmp_path, "cat-1"))


def _set_status(data_dir: Path, cid: str, status: str) -> None:
    db = Database(f"sqlite:///{data_dir / 'scengen.db'}")
    try:
        with db.session() as s:
            repo.get_catalogue(s, cid).status = status
    finally:
        db.dispose()


def test_the_service_leaves_a_job_its_previous_holder_ended(
        store: tuple[Path, dict[str, str]]) -> None:
    """What the service runs once a lock is free: only a job still queued or running (a
    CLI that cancelled or failed it meanwhile has the last word)."""
    data_dir, _ = store
    ctx = open_context(make_settings(data_dir))
    try:
        cid = catalogues.create(ctx, n=N, seed=5, constraints=["ttc<3"], chunk_size=CHUNK).id
        _set_status(data_dir, cid, "cancelled")
        assert ctx.runner().run(cid, only_active=True) == "cancelled"
    finally:
        ctx.close()
    assert _catalogues(data_dir) == [(cid, "cancelled")]
    assert chunk_indices_in_store(data_dir, cid) == []
    assert not _lock_file(data_dir, cid).exists()


def test_ctrl_c_cancels_the_job_before_its_lock_is_released(
        store: tuple[Path, dict[str, str]], monkeypatch: pytest.MonkeyPatch) -> None:
    """A service waiting for the lock must find the job cancelled, not still running."""
    from app.jobs.runner import CatalogueRunner

    data_dir, _ = store
    seen: list[list[tuple[str, str]]] = []
    release = joblock.release

    def interrupted(*args: object) -> str:
        raise KeyboardInterrupt

    def noting(lock: joblock.JobLock) -> None:
        seen.append(_catalogues(data_dir))
        release(lock)

    monkeypatch.setattr(CatalogueRunner, "_run", interrupted)
    monkeypatch.setattr(joblock, "release", noting)
    ctx = open_context(make_settings(data_dir))
    try:
        cid = catalogues.create(ctx, n=N, seed=5, constraints=["ttc<3"], chunk_size=CHUNK).id
        with pytest.raises(KeyboardInterrupt):
            ctx.runner().run(cid)
    finally:
        ctx.close()
    assert seen == [[(cid, "cancelled")]]
    assert not _lock_file(data_dir, cid).exists()


def _refusal(cid: str, pid: int) -> str:
    return (f"scengen: error: catalogue {cid} is being run by another process on this "
            f"store (pid {pid}); left to it: resume it here only if that process ends "
            "before the job does")


def test_resume_of_a_held_job_is_refused_before_its_pool_starts(
        store: tuple[Path, dict[str, str]], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The refusal comes before the pool's workers start (their start and warm-up took
    seconds first); the job, its lock and the store are left as they were."""
    from app.cli import main
    from app.jobs.executors import InlineExecutor
    from app.settings import get_settings

    data_dir, _ = store
    ctx = open_context(make_settings(data_dir))
    try:
        cid = catalogues.create(ctx, n=N, seed=5, constraints=["ttc<3"], chunk_size=CHUNK).id
    finally:
        ctx.close()
    started: list[dict[str, object]] = []

    def make_executor(**kwargs: object) -> InlineExecutor:
        started.append(kwargs)
        return InlineExecutor()

    monkeypatch.setattr("app.jobs.executors.make_executor", make_executor)
    for name in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("SCENGEN_DATA_DIR", str(data_dir))
    get_settings.cache_clear()
    # held through another open file of this process: refused as another process's lock
    held = joblock.acquire(data_dir, cid)
    try:
        code = main(["catalogue", "resume", cid, "-q"])
        assert _lock_file(data_dir, cid).read_text() == f"{os.getpid()}\n"
    finally:
        joblock.release(held)
        get_settings.cache_clear()
    assert code == 2 and started == []
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [_refusal(cid, os.getpid())]
    assert captured.out == ""
    assert _catalogues(data_dir) == [(cid, "queued")]
    assert chunk_indices_in_store(data_dir, cid) == []


@pytest.mark.slow
def test_resume_of_a_job_a_service_runs_exits_2_and_the_service_finishes_it(
        store: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    data_dir, env = store
    ctx = open_context(make_settings(data_dir))
    try:
        cid = catalogues.create(ctx, n=N, seed=5, constraints=["ttc<3"], chunk_size=CHUNK).id
    finally:
        ctx.close()
    log = tmp_path / "serve.log"
    with serve_service(env, log) as (service, _):
        wait_for(lambda: f"{cid}: 0 of" in log.read_text(), "the service to run the job",
                 attempts=1200)
        workers = _workers_of(service.pid)
        _signal_all(workers, signal.SIGSTOP)  # the job stays live however long we take
        try:
            resumed = subprocess.run(_cli("resume", cid), cwd=ROOT, env=env,
                                     capture_output=True, text=True, timeout=300)
        finally:
            _signal_all(workers, signal.SIGCONT)
        assert resumed.returncode == 2, resumed.stderr[-2000:]
        assert resumed.stderr.splitlines() == [_refusal(cid, service.pid)]
        assert resumed.stdout == ""
        wait_for(lambda: status_in_store(data_dir, cid) == "done", "the job to finish",
                 attempts=3000)
    assert log.read_text().count(f"{cid}: done") == 1
    assert chunk_indices_in_store(data_dir, cid) == list(range(N // CHUNK))
    assert not _lock_file(data_dir, cid).exists()


def _start_create(env: dict[str, str], data_dir: Path,
                  out: Path) -> tuple[subprocess.Popen[bytes], str, list[int]]:
    """A CLI ``catalogue create`` holding its job, its pool worker stopped (so the job is
    live for as long as the test needs): the process, the catalogue id, the workers."""
    with open(out, "wb") as fh:
        cli = subprocess.Popen(_cli("create", "-n", str(N), "--chunk-size", str(CHUNK),
                                    "--seed", "7"),
                               cwd=ROOT, env=env, stdout=fh, stderr=fh)

    def running() -> bool:
        assert cli.poll() is None, out.read_text()[-2000:]
        if not (data_dir / "scengen.db").is_file():
            return False
        try:
            return [s for _, s in _catalogues(data_dir)] == ["running"]
        except OperationalError:  # the file is there before the CLI has made its tables
            return False

    try:
        wait_for(running, "the CLI to run its job", attempts=1200)
        [(cid, _)] = _catalogues(data_dir)
        workers = _workers_of(cli.pid)
        _signal_all(workers, signal.SIGSTOP)
    except BaseException:
        cli.kill()  # never leave the CLI running behind a failed start
        cli.wait()
        raise
    return cli, cid, workers


@contextmanager
def _cli_job_left_by_a_service(env: dict[str, str], data_dir: Path, tmp_path: Path
                               ) -> Iterator[tuple[subprocess.Popen[bytes], str, list[int]]]:
    """A CLI ``catalogue create`` running its job (``_start_create``, output in
    ``cli.out``) and a service started beside it (log in ``serve.log``) that has left the
    job to it; yields (the CLI, the catalogue id, its stopped workers) inside the
    service's life. The CLI is stopped afterwards if the test left it running."""
    cli, cid, workers = _start_create(env, data_dir, tmp_path / "cli.out")
    try:
        log = tmp_path / "serve.log"
        with serve_service(env, log):
            wait_for(lambda: _left(log, f"catalogue {cid} is being run by another process "
                                   f"(pid {cli.pid}): left to it"),
                     "the service to leave the job to the CLI", attempts=1200)
            yield cli, cid, workers
    finally:
        if cli.poll() is None:
            _signal_all(workers, signal.SIGCONT)
            cli.kill()
            cli.wait()


@pytest.mark.slow
def test_a_service_leaves_a_job_the_cli_runs_to_the_cli(
        store: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    data_dir, env = store
    log = tmp_path / "serve.log"
    with _cli_job_left_by_a_service(env, data_dir, tmp_path) as (cli, cid, workers):
        _signal_all(workers, signal.SIGCONT)
        assert cli.wait(timeout=600) == 0, (tmp_path / "cli.out").read_text()[-2000:]
        wait_for(lambda: f"catalogue {cid}: done by the process that ran it"
                 in log.read_text(), "the service to see the job done", attempts=600)
    assert RUNNING not in log.read_text()  # it never ran the job
    assert f'{{"id": "{cid}", "status": "done"}}' in (tmp_path / "cli.out").read_text()
    assert chunk_indices_in_store(data_dir, cid) == list(range(N // CHUNK))
    assert not _lock_file(data_dir, cid).exists()


@pytest.mark.slow
def test_a_service_takes_over_the_job_of_a_killed_cli(
        store: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    data_dir, env = store
    log = tmp_path / "serve.log"
    with _cli_job_left_by_a_service(env, data_dir, tmp_path) as (cli, cid, _):
        cli.kill()  # SIGKILL, the CLI alone: no clean-up runs; its worker dies with it
        cli.wait(timeout=60)
        wait_for(lambda: status_in_store(data_dir, cid) == "done",
                 "the service to take the job over and finish it", attempts=3000)
    assert log.read_text().count(RUNNING) == 1
    assert chunk_indices_in_store(data_dir, cid) == list(range(N // CHUNK))
    assert not _lock_file(data_dir, cid).exists()
