"""Load test of the fair queue (issue 27 item 1): 8 clients for 60 s, one of them flooding.

Against ``uvicorn app.main:app`` started here (2 local workers, the real default model),
twice, with a fresh database each time:

* **fair** (the service as configured: ``SCENGEN_RUNNING_JOBS_LIMIT`` default, jobs of
  different clients share the workers chunk by chunk, ``app/jobs/fair.py``);
* **baseline**: ``SCENGEN_RUNNING_JOBS_LIMIT=1``, one job at a time as before issue 27
  (the queue still starts the next job of another client first, so the baseline is
  *kinder* than the old first-in-first-out queue).

Client 1 floods: it posts catalogues of ``--flood-n`` scenarios as fast as its quota lets
it (429s are counted and retried after 1 s). Once its first job runs, clients 2 … 8 each
post a catalogue of ``--small-n`` scenarios, poll it every 0.5 s until done, and post the
next, for ``--seconds`` s. Each client talks from its own loopback address (127.0.0.k):
the service counts clients by peer address. Printed per run: the small catalogues
finished and their time from POST to done (median, max), the scenarios the small clients
and the flooder got stored, the flooder's 429s, /health p50/p99; then fair/baseline
ratios. The load average (``/proc/loadavg``) is printed with every figure: the machine is
shared, say so when quoting them.

    .venv/bin/python benchmarks/bench_load.py                 # 2 x 60 s plus start-ups
    .venv/bin/python benchmarks/bench_load.py --seconds 20    # a quick look

The first start fits the default model (a minute or two) in ``--cache`` (kept between
runs; default /tmp/scengen-bench-load-cache).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
from local_service import Server, load, percentile

CONSTRAINTS = ["ttc<3"]


def client(base: str, k: int) -> httpx.Client:
    """A client talking from loopback address 127.0.0.k (its own peer address)."""
    return httpx.Client(base_url=base, timeout=60,
                        transport=httpx.HTTPTransport(local_address=f"127.0.0.{k}"))


def run_phase(base: str, args: argparse.Namespace) -> dict[str, Any]:
    stop = threading.Event()
    lock = threading.Lock()
    flood_ids: list[str] = []
    counts = {"flood_429": 0, "flood_202": 0}
    small_done: list[float] = []  # seconds from POST to done
    small_ids: list[str] = []
    health: list[float] = []
    errors: list[str] = []
    flood_running = threading.Event()

    def flooder() -> None:
        with client(base, 2) as c:
            seed = 1000
            while not stop.is_set():
                r = c.post("/catalogues", json={"n": args.flood_n, "seed": seed,
                                                "constraints": CONSTRAINTS})
                if r.status_code == 202:
                    seed += 1
                    with lock:
                        flood_ids.append(r.json()["id"])
                        counts["flood_202"] += 1
                    continue
                if r.status_code == 429:
                    with lock:
                        counts["flood_429"] += 1
                    stop.wait(1.0)
                    continue
                errors.append(f"flood: {r.status_code} {r.text[:200]}")
                stop.wait(1.0)

    def watch_flood() -> None:
        with client(base, 2) as c:
            while not stop.is_set() and not flood_running.is_set():
                with lock:
                    first = flood_ids[0] if flood_ids else None
                if first is not None:
                    st = c.get(f"/catalogues/{first}").json()
                    if st.get("scenarios_done", 0) > 0:
                        flood_running.set()
                        return
                stop.wait(0.2)

    def small(k: int) -> None:
        flood_running.wait(args.seconds * 3)
        seed = 10 * k
        with client(base, k) as c:
            while not stop.is_set():
                t0 = time.monotonic()
                r = c.post("/catalogues", json={"n": args.small_n, "seed": seed,
                                                "constraints": CONSTRAINTS})
                seed += 1
                if r.status_code != 202:
                    errors.append(f"client {k}: {r.status_code} {r.text[:200]}")
                    stop.wait(1.0)
                    continue
                cid = r.json()["id"]
                with lock:
                    small_ids.append(cid)
                while not stop.is_set():
                    st = c.get(f"/catalogues/{cid}").json()
                    if st["status"] == "done":
                        with lock:
                            small_done.append(time.monotonic() - t0)
                        break
                    if st["status"] in ("failed", "cancelled"):
                        errors.append(f"client {k}: {cid} {st['status']}: {st.get('error')}")
                        break
                    stop.wait(0.5)

    def prober() -> None:
        with client(base, 10) as c:
            while not stop.is_set():
                t0 = time.monotonic()
                c.get("/health")
                health.append(time.monotonic() - t0)
                stop.wait(0.5)

    threads = [threading.Thread(target=flooder), threading.Thread(target=watch_flood),
               threading.Thread(target=prober)]
    threads += [threading.Thread(target=small, args=(k,)) for k in range(3, 10)]
    for t in threads:
        t.start()
    flood_running.wait(args.seconds * 3)
    t_start = time.monotonic()
    stop.wait(args.seconds)
    stop.set()
    for t in threads:
        t.join(120)
    elapsed = time.monotonic() - t_start
    with client(base, 11) as c:
        def stored(cid: str) -> int:
            return int(c.get(f"/catalogues/{cid}").json().get("scenarios_stored", 0))

        small_stored = sum(stored(cid) for cid in small_ids)
        flood_stored = sum(stored(cid) for cid in flood_ids)
    return {
        "seconds": round(elapsed, 1),
        "small_catalogues_posted": len(small_ids),
        "small_catalogues_done": len(small_done),
        "small_done_median_s": round(statistics.median(small_done), 1) if small_done else None,
        "small_done_max_s": round(max(small_done), 1) if small_done else None,
        "small_scenarios_stored": small_stored,
        "flood_scenarios_stored": flood_stored,
        "flood_jobs_admitted": counts["flood_202"], "flood_429": counts["flood_429"],
        "health_p50_ms": round(1000 * percentile(health, 0.5), 1),
        "health_p99_ms": round(1000 * percentile(health, 0.99), 1),
        "errors": errors[:5], "load": load(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--flood-n", type=int, default=50_000)
    ap.add_argument("--small-n", type=int, default=250)
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir())
                    / "scengen-bench-load-cache")
    ap.add_argument("--only", default="fair,baseline")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="scengen-bench-load-"))
    results: dict[str, Any] = {"cpu_count": os.cpu_count(), "seconds": args.seconds,
                               "flood_n": args.flood_n, "small_n": args.small_n}
    phases = {"fair": {}, "baseline": {"SCENGEN_RUNNING_JOBS_LIMIT": "1"}}
    try:
        for name in args.only.split(","):
            db = work / f"{name}.db"
            env = {"SCENGEN_LOCAL_WORKERS": "2", "SCENGEN_DATABASE_URL": f"sqlite:///{db}",
                   "SCENGEN_RESUME_JOBS": "0", **phases[name]}
            print(f"{name}: starting the service (log {work / 'server.log'})  [{load()}]",
                  file=sys.stderr, flush=True)
            server = Server(args.cache, env, work / "server.log")
            try:
                server.wait(ready=True)
                results[name] = run_phase(server.base, args)
            finally:
                server.stop()
            print(f"{name}: {json.dumps(results[name])}", file=sys.stderr, flush=True)
        if "fair" in results and "baseline" in results:
            f, b = results["fair"], results["baseline"]
            results["ratio_small_done_fair_over_baseline"] = (
                f["small_catalogues_done"] / b["small_catalogues_done"]
                if b["small_catalogues_done"] else None)
            for r in (f, b):
                r["all_scenarios_stored"] = (r["small_scenarios_stored"]
                                             + r["flood_scenarios_stored"])
            results["ratio_all_scenarios_fair_over_baseline"] = round(
                f["all_scenarios_stored"] / max(1, b["all_scenarios_stored"]), 2)
            results["ratio_small_scenarios_fair_over_baseline"] = (
                f["small_scenarios_stored"] / b["small_scenarios_stored"]
                if b["small_scenarios_stored"] else None)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
