"""The first scored request against the second, from a cold ``scengen serve`` (issue 25 item 4).

Starts ``scengen serve`` as a user would (a fresh store unless ``--model-cache``), waits for
``/health`` to answer and, unless ``--no-wait-ready``, for its ``status`` to be ``ok``
(``warming`` while the start-up warm-up runs), then times the README's first request
(``POST /scenarios`` n=10, seed 1, ttc<3, scored) twice. Run twice over:

* numba cache cold: ``NUMBA_CACHE_DIR`` an empty directory (a fresh install);
* numba cache warm: the same directory again, now filled by the first run.

Prints time to /health answering, time to ready, first and second request and their ratio,
with the load average. Nothing asserts on time.

    .venv/bin/python benchmarks/bench_first_request.py [--model-cache DIR] [--keep-numba DIR]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
from local_service import free_port, load, service_env, stop_group

ROOT = Path(__file__).resolve().parents[1]
BODY = {"n": 10, "seed": 1, "constraints": ["ttc<3"], "score": True}


def one_start(data_dir: Path, numba_dir: Path, wait_ready: bool, log: Path) -> dict[str, float]:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    env = service_env(data_dir, {"NUMBA_CACHE_DIR": str(numba_dir)})
    scengen = Path(sys.executable).with_name("scengen")
    t0 = time.monotonic()
    with open(log, "ab") as out:
        proc = subprocess.Popen([str(scengen), "serve", "--port", str(port),
                                 "--log-level", "warning"], cwd=ROOT, env=env, stdout=out,
                                stderr=out, start_new_session=True)
    try:
        answered = ready = None
        while ready is None:
            if proc.poll() is not None:
                raise SystemExit(f"scengen serve exited with {proc.returncode}; see {log}")
            try:
                r = httpx.get(f"{base}/health", timeout=10)
                if r.status_code == 200:
                    answered = answered or time.monotonic() - t0
                    if not wait_ready or r.json().get("status") == "ok":
                        ready = time.monotonic() - t0
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        times = []
        for _ in range(2):
            t = time.monotonic()
            r = httpx.post(f"{base}/scenarios", json=BODY, timeout=600)
            r.raise_for_status()
            times.append(time.monotonic() - t)
        assert answered is not None
        return {"health_answers_s": answered, "ready_s": ready, "first_s": times[0],
                "second_s": times[1]}
    finally:
        stop_group(proc, 60)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model-cache", type=Path, default=None,
                    help="copy the cached table and model from this data dir (else fitted)")
    ap.add_argument("--no-wait-ready", action="store_true",
                    help="send the first request as soon as /health answers 200")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="scengen-first-") as tmp:
        numba_dir = Path(tmp) / "numba"
        numba_dir.mkdir()
        for label in ("numba cache cold", "numba cache warm"):
            data_dir = Path(tmp) / f"store-{label.split()[-1]}"
            if args.model_cache:
                for sub in ("tables", "models"):
                    if (args.model_cache / sub).is_dir():
                        shutil.copytree(args.model_cache / sub, data_dir / sub)
            r = one_start(data_dir, numba_dir, not args.no_wait_ready, Path(tmp) / "serve.log")
            print(f"{label}: /health answers {r['health_answers_s']:.1f} s, ready "
                  f"{r['ready_s']:.1f} s; POST /scenarios n=10 scored: first "
                  f"{r['first_s']:.2f} s, second {r['second_s']:.2f} s, ratio "
                  f"{r['first_s'] / r['second_s']:.1f}  [{load()}]", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
