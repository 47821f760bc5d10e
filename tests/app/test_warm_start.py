"""Issue 25 item 4: once /health says "ok", the README's first scored request loads no
compiled kernel the start-up warm-up did not load already.

Measured before the fix (fresh numba cache): the first POST /scenarios n=10 waited 12-15 s
after "ok" while the second took 0.3-0.5 s, because the request's parameter arrays were
writable and the warm-up's read-only: numba compiles one machine-code version per
read-only flag, so the request compiled the criticality kernels (``_all``, ``_one``,
``_cutter_samples``, ``_bound_kernel``) a second time.

The service runs in a fresh interpreter (nothing loaded yet) with numba's compile event
every kernel's signatures listed when /health says "ok" and after the requests (compiled
or loaded from the on-disk cache alike: the test does not depend on that cache).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.browser.factories import prepare_data_dir

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import json, sys, time
from numba.core.registry import CPUDispatcher


def loaded():
    # every (kernel, signature) compiled or loaded from numba's cache in this process
    out = set()
    for mod in list(sys.modules.values()):
        if not getattr(mod, "__name__", "").startswith(("riskcore", "sampler", "datasets",
                                                        "app")):
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher):
                f = obj.py_func
                out.update(f"{f.__module__}.{f.__qualname__}{sig}" for sig in obj.overloads)
    return out


from fastapi.testclient import TestClient
from app.main import create_app
from app.settings import Settings

settings = Settings(data_dir=sys.argv[1], local_workers=0, warm_start=True,
                    trusted_hosts=["testserver"], sync_budget_seconds=600.0)
with TestClient(create_app(settings)) as client:
    for _ in range(6000):
        if client.get("/health").json()["status"] == "ok":
            break
        time.sleep(0.1)
    else:
        raise SystemExit("never ready")
    ready = loaded()
    for body in ({"n": 10, "seed": 1, "constraints": ["ttc<3"], "score": True},
                 {"n": 3, "seed": 2, "constraints": ["ttc<3"], "score": True}):
        r = client.post("/scenarios", json=body)
        assert r.status_code == 200, r.text
    print(json.dumps({"ready": sorted(ready), "late": sorted(loaded() - ready)}))
"""


@pytest.mark.slow
def test_the_first_request_after_ready_loads_no_kernel(tmp_path: Path) -> None:
    data_dir = prepare_data_dir(tmp_path / "data")
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(data_dir)], cwd=ROOT,
                          capture_output=True, text=True, timeout=1800, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(loaded["ready"]) >= 5, "the warm-up loaded (almost) no kernel"
    assert loaded["late"] == [], "loaded by the first requests after 'ok'"
