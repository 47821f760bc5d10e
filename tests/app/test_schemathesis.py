"""Issue 14: schemathesis (its CLI, every check) over the live OpenAPI of a running service:
at least 1,000 generated cases and no failure of any check. Configuration and the reasons
for each setting: tests/app/schemathesis.toml. The service runs with small work limits so
that the fuzzer's requests stay cheap (they are the limits under test, not a shortcut)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.app.factories import copy_model_cache, service_env, uvicorn_service, wait_for

CONFIG = Path(__file__).with_name("schemathesis.toml")
SMALL_LIMITS = {
    "local_workers": "0", "chunk_size": "5", "resume_jobs": "false",
    "sync_n_limit": "3", "catalogue_n_limit": "20", "upload_limit_bytes": "200000",
    "model_n_init_limit": "1", "model_k_limit": "3", "model_report_samples_limit": "2000",
    "model_max_iter_limit": "100", "model_cv_folds_limit": "3",
    "risk_objects_limit": "4", "risk_steps_limit": "200",
    # the fuzzer is one client firing thousands of requests: the per-client quotas (their own
    # tests: tests/app/test_quotas.py) would answer most of its POSTs with 429
    "client_jobs_limit": "1000000", "client_queued_scenarios_limit": "1000000000",
    # the service's own budget (not the tests' generous one): the response-time check of
    # schemathesis.toml (15 s) is derived from it
    "sync_budget_seconds": "10",
}


def _schemathesis() -> str:
    exe = Path(sys.executable).with_name("schemathesis")
    found = str(exe) if exe.is_file() else shutil.which("schemathesis")
    if found is None:
        pytest.fail("schemathesis is not installed (make test installs the dev extras)")
    return found


@pytest.fixture
def server(tmp_path: Path, model_cache_dir: Path) -> Iterator[str]:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    env = service_env(data_dir, **SMALL_LIMITS)
    with uvicorn_service(env, tmp_path / "uvicorn.log", "--log-level", "warning") as base:
        yield base


@pytest.mark.slow
def test_schemathesis_finds_nothing(server: str, tmp_path: Path) -> None:
    with httpx.Client(base_url=server, timeout=120) as http:
        r = http.post("/catalogues", json={"n": 4, "seed": 1, "score": False})
        assert r.status_code == 202, r.text
        cid = r.json()["id"]
        wait_for(lambda: http.get(f"/catalogues/{cid}").json()["status"] == "done",
                 "the seed catalogue", attempts=1200)
    env = {**os.environ, "SCENGEN_ST_CATALOGUE": cid}
    run = subprocess.run(
        [_schemathesis(), "--config-file", str(CONFIG), "run", f"{server}/openapi.json",
         # one worker: with two, the stateful phase once reported ST302 (a catalogue
         # POST made was not found by the GET after it). 40 POST-then-GET pairs by hand
         # all found theirs and one worker passes: most likely the other worker's
         # DELETE (its links reach catalogue ids too) removed it in between
         "--checks", "all", "--max-examples", "25", "--workers", "1", "--seed", "1",
         "--generation-database", "none", "--no-color", "--report-dir", str(tmp_path)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1500)
    out = run.stdout + run.stderr
    generated = re.search(r"(\d+) generated", out)
    assert generated is not None, out[-3000:]
    assert int(generated.group(1)) >= 1000, out[-3000:]
    summary = out.split("SUMMARY")[-1]
    assert "Failures:" not in summary and "Errors:" not in summary, out[-6000:]
    assert run.returncode == 0, out[-6000:]
