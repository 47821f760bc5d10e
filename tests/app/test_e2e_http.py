"""End to end over real HTTP: uvicorn in a subprocess on a free loopback port."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.app.factories import copy_model_cache, free_port, service_env, wait_for

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def server(tmp_path: Path, model_cache_dir: Path) -> Iterator[str]:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    port = free_port()
    env = service_env(data_dir, local_workers="1", chunk_size="3")
    log = tmp_path / "uvicorn.log"
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "app.main:app", "--host", "127.0.0.1",
             "--port", str(port)], cwd=ROOT, env=env, stdout=log_file, stderr=log_file,
            start_new_session=True)
    base = f"http://127.0.0.1:{port}"

    def up() -> bool:
        if proc.poll() is not None:
            raise AssertionError(f"uvicorn exited: {log.read_text()[-2000:]}")
        try:
            return httpx.get(f"{base}/health", timeout=2).status_code == 200
        except httpx.TransportError:
            return False

    try:
        wait_for(up, "uvicorn to answer /health", attempts=1200)
        yield base
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)


def test_sample_catalogue_export_over_http(server: str) -> None:
    with httpx.Client(base_url=server, timeout=300) as http:
        r = http.post("/scenarios", json={"n": 3, "seed": 1, "constraints": ["ttc<3"]})
        assert r.status_code == 200, r.text
        params = [s["params"] for s in r.json()["scenarios"]]
        assert len(params) == 3
        assert all(p["dv"] > 0 and p["gap"] / p["dv"] < 3 for p in params)  # TTC by hand
        r = http.post("/catalogues", json={"n": 5, "seed": 4})
        assert r.status_code == 202
        cid = r.json()["id"]
        state: dict[str, str] = {}

        def finished() -> bool:
            state.update(http.get(f"/catalogues/{cid}").json())
            return state["status"] in ("done", "failed")

        wait_for(finished, "the catalogue", attempts=3000)
        assert state["status"] == "done"
        r = http.get(f"/catalogues/{cid}/export", params={"format": "csv"})
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
        assert len(r.text.strip().splitlines()) == 1 + 5
        r = http.post("/scenarios", json={"n": 10_000})
        assert r.status_code == 422 and r.json()["error"]["field"] == "body.n"
        r = http.get("/catalogues/nope")
        assert r.status_code == 404
