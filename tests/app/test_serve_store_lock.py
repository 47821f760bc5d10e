"""One `scengen serve` per store, for real: each service resumes the store's unfinished
jobs when it starts, so a second one on the same store (another port) ran the same job
twice at once. Now the second exits 2 with one line naming the store and the service
that holds it; a SIGKILLed service leaves no stale lock."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

import httpx
import pytest

from app.services import catalogues
from app.services.store import open_context
from tests.app.factories import (
    chunk_indices_in_store,
    copy_model_cache,
    free_port,
    make_settings,
    serve_cmd,
    serve_service,
    service_env,
    status_in_store,
    wait_for,
)

ROOT = Path(__file__).resolve().parents[2]
#: 20 chunks on one worker: the job is still running while the second service tries
N, CHUNK = 40, 2


def _second(env: dict[str, str]) -> tuple[subprocess.CompletedProcess[str], str]:
    """Another `scengen serve` on the store, on a free port; it must end by itself (a
    service that started is stopped after 120 s and fails the test)."""
    port = free_port()
    proc = subprocess.Popen(serve_cmd(port), cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        pytest.fail(f"a second scengen serve on the store started: {err[-2000:]}")
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err), \
        f"http://127.0.0.1:{port}"


def _refusal(data_dir: Path, pid: int, base: str) -> str:
    return (f"scengen: error: --data-dir: the store {data_dir.resolve()} is in use by another "
            f"scengen serve (pid {pid}, {base}); stop it or choose another --data-dir")


@pytest.fixture
def unfinished(tmp_path: Path, model_cache_dir: Path) -> tuple[Path, str, dict[str, str]]:
    """A store with a queued catalogue (which a service resumes when it starts): its data
    dir, the catalogue's id and the services' environment."""
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    ctx = open_context(make_settings(data_dir))
    try:
        cid = catalogues.create(ctx, n=N, seed=5, constraints=["ttc<3"], chunk_size=CHUNK).id
    finally:
        ctx.close()
    return data_dir, cid, service_env(data_dir, local_workers="1", warm_start="0")


def _status(base: str, cid: str) -> str:
    status: str = httpx.get(f"{base}/catalogues/{cid}", timeout=10).json()["status"]
    return status


RESUMING = "resuming unfinished catalogue"


def test_a_store_in_use_stops_serve_before_the_port_and_the_app(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The store is checked first: with its port busy too, the line names the service
    that holds the store (and so where it listens); nothing starts, nothing is written."""
    import fcntl
    import socket

    import uvicorn

    from app.cli import main
    from app.settings import get_settings

    started: list[object] = []
    monkeypatch.setattr(uvicorn, "Server", lambda config: started.append(config))
    data_dir = tmp_path / "store"
    data_dir.mkdir()
    held = data_dir / "serve.lock"
    held.write_text("4242 http://127.0.0.1:8123\n")
    busy = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    with open(held, "rb") as holder:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        try:
            get_settings.cache_clear()
            code = main(["serve", "--data-dir", str(data_dir), "--port",
                         str(busy.getsockname()[1])])
        finally:
            busy.close()
            get_settings.cache_clear()
    assert code == 2 and started == []
    assert capsys.readouterr().err.splitlines() == [
        _refusal(data_dir, 4242, "http://127.0.0.1:8123")]
    assert [f.name for f in data_dir.iterdir()] == ["serve.lock"]
    assert held.read_text() == "4242 http://127.0.0.1:8123\n"


@pytest.mark.slow
def test_a_second_service_on_the_store_exits_2_and_runs_nothing(
        unfinished: tuple[Path, str, dict[str, str]], tmp_path: Path) -> None:
    data_dir, cid, env = unfinished
    log = tmp_path / "first.log"
    with serve_service(env, log) as (first, base):
        wait_for(lambda: RESUMING in log.read_text(), "the first service to resume the job")
        second, second_base = _second(env)
        assert _status(base, cid) in ("queued", "running")  # the job was live meanwhile
        assert second.returncode == 2, second.stderr[-2000:]
        assert second.stderr.splitlines() == [_refusal(data_dir, first.pid, base)]
        assert second.stdout == ""
        with pytest.raises(httpx.TransportError):  # it never listened
            httpx.get(f"{second_base}/health", timeout=2)
        # the first keeps serving and finishes the job, each chunk once
        assert httpx.get(f"{base}/health", timeout=10).status_code == 200
        wait_for(lambda: _status(base, cid) == "done", "the job to finish", attempts=3000)
    assert log.read_text().count(RESUMING) == 1
    assert chunk_indices_in_store(data_dir, cid) == list(range(N // CHUNK))


@pytest.mark.slow
def test_a_killed_service_leaves_no_lock_and_the_next_resumes(
        unfinished: tuple[Path, str, dict[str, str]], tmp_path: Path) -> None:
    data_dir, cid, env = unfinished
    log = tmp_path / "first.log"
    with serve_service(env, log) as (first, _):
        wait_for(lambda: RESUMING in log.read_text(), "the first service to resume the job")
        os.kill(first.pid, signal.SIGKILL)  # the service alone, as a user would
        first.wait(timeout=60)
        assert status_in_store(data_dir, cid) in ("queued", "running")
        log2 = tmp_path / "next.log"
        with serve_service(env, log2) as (after, base2):
            wait_for(lambda: RESUMING in log2.read_text(), "the next service to resume")
            # it holds the store now: a further one names it, not the killed one
            third, _ = _second(env)
            assert third.returncode == 2, third.stderr[-2000:]
            assert third.stderr.splitlines() == [_refusal(data_dir, after.pid, base2)]
            wait_for(lambda: _status(base2, cid) == "done", "the resumed job to finish",
                     attempts=3000)
    assert chunk_indices_in_store(data_dir, cid) == list(range(N // CHUNK))

