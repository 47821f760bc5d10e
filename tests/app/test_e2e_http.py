"""End to end over real HTTP: uvicorn in a subprocess on a free loopback port."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.app.factories import copy_model_cache, service_env, uvicorn_service, wait_for


@pytest.fixture
def server(tmp_path: Path, model_cache_dir: Path) -> Iterator[str]:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    env = service_env(data_dir, local_workers="1", chunk_size="3")
    with uvicorn_service(env, tmp_path / "uvicorn.log") as base:
        yield base


@pytest.mark.slow
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
