"""Evaluations end to end with the real simulator (``sampler.campaign.sut_runner`` over
``riskcore.sut``): over HTTP, from the CLI, and with a SUT installed from examples/ as a
package that registers it under the entry-point group ``scengen.suts``."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.app.factories import copy_model_cache, make_settings, wait_for

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "sut-package"

#: minutes on a busy 2-core machine (the simulator, numba compilation in subprocesses)
pytestmark = pytest.mark.slow


def test_http_evaluation_with_the_real_simulator(model_cache_dir: Path,
                                                 tmp_path: Path) -> None:
    from fastapi.testclient import TestClient

    from tests.app.factories import make_app

    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    with TestClient(make_app(make_settings(data_dir))) as client:
        r = client.post("/evaluations", json={"sut": "acc", "n": 300, "seed": 3,
                                              "batch_size": 150})
        assert r.status_code == 202, r.text
        eid = r.json()["id"]
        wait_for(lambda: client.get(f"/evaluations/{eid}").json()["status"]
                 in ("done", "failed"), "the evaluation", attempts=3000)
        st = client.get(f"/evaluations/{eid}").json()
        assert st["status"] == "done", st["error"]
        s = st["summary"]
        assert s["runs"] == 300 and s["sut"] == "acc"
        assert s["sut_runs"] == st["runs_simulated"]
        page = client.get(f"/evaluations/{eid}/runs",
                          params={"order_by": "run", "desc": "false", "limit": 1000}).json()
        assert page["total"] == st["runs_simulated"]
        for rec in page["runs"]:
            assert rec["vs_careful"] in ("worse", "same", "better")
            assert rec["collided"] == (rec["impact_speed"] > 0)
            assert rec["violation"] == (rec["must_avoid"] and rec["collided"])
        hits = [rec for rec in page["runs"] if rec["collided"]]
        assert len(hits) == s["collisions"]
        # the estimate is sum(weight * collided) / draws
        est = sum(rec["weight"] for rec in hits) / s["runs"]
        assert est == pytest.approx(s["p_collision"]["estimate"], rel=1e-9, abs=1e-300)
        if hits:
            r = client.get(f"/evaluations/{eid}/export", params={"format": "xosc"})
            assert r.status_code == 200 and r.content[:2] == b"PK"


def _env(store: Path, extra_path: Path | None = None) -> dict[str, str]:
    env = dict(os.environ, SCENGEN_DATA_DIR=str(store), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_WARM_START="0", SCENGEN_SYNC_BUDGET_SECONDS="600")
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            [str(extra_path), str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _scengen(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=1200)


def test_an_installed_example_package_is_evaluated(store: Path, tmp_path: Path) -> None:
    """pip-install examples/sut-package into a private target directory (the project's
    environment is left as it is), then 'scengen evaluate' finds its entry points."""
    src = tmp_path / "sut-package"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("*.egg-info", "build",
                                                                "__pycache__"))
    target = tmp_path / "site"
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                          "--disable-pip-version-check", "--target", str(target), str(src)],
                         capture_output=True, text=True, timeout=600)
    if pip.returncode != 0 and "setuptools" in (pip.stderr + pip.stdout):
        pytest.skip("no build backend available to pip (offline without setuptools): "
                    + (pip.stderr.strip().splitlines() or ["?"])[-1])
    assert pip.returncode == 0, pip.stderr[-2000:]
    assert any(p.name.startswith("scengen_example_sut") and p.suffix == ".dist-info"
               for p in target.iterdir())
    env = _env(store, target)
    listed = _scengen(["evaluate", "--list-suts"], env, tmp_path)
    assert listed.returncode == 0, listed.stderr
    names = {s["name"]: s for s in json.loads(listed.stdout)}
    assert names["example_gap_keeper"]["origin"] == "entry point (scengen-example-sut)"
    assert names["example_gap_keeper"]["parameters"]["time_gap"][1] == "s"
    assert "example_late_braker" in names and "acc" in names
    runs = tmp_path / "runs.jsonl"
    done = _scengen(["evaluate", "--sut", "example_gap_keeper", "-n", "200", "--seed", "2",
                     "--sut-param", "time_gap=1.2", "--runs", str(runs)], env, tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    summary: dict[str, Any] = json.loads(done.stdout)
    assert summary["sut"] == "example_gap_keeper" and summary["runs"] == 200
    lines = [json.loads(x) for x in runs.read_text().splitlines()]
    assert len(lines) == 200
    assert sum(x["collided"] for x in lines) == summary["collisions"]
    # the per-run one goes through riskcore.sut.per_run
    per_run = _scengen(["evaluate", "--sut", "example_late_braker", "-n", "60", "-q"], env,
                       tmp_path)
    assert per_run.returncode == 0, per_run.stderr[-3000:]
    assert json.loads(per_run.stdout)["runs"] == 60
    # an unknown name: one line, exit 2
    bad = _scengen(["evaluate", "--sut", "example_nope", "-n", "5"], env, tmp_path)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "example_gap_keeper" in bad.stderr  # it lists what is registered
