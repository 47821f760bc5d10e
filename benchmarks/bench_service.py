"""Benchmark of the running service over loopback (issue 5).

Measures, against ``uvicorn app.main:app`` started here in a subprocess:

1. p50 and p95 latency of ``POST /scenarios`` with n = 100 and scoring;
2. the time to build a scored catalogue of ``--catalogue-n`` scenarios (default 10,000)
   on the local process pool (``--workers`` processes), from POST /catalogues to status
   ``done``;
3. the same on a two-worker ``dask.distributed.LocalCluster`` (the service reaches it
   through ``SCENGEN_DASK_SCHEDULER``), and the Dask/local ratio;
4. that both catalogues (same seed) export to the same CSV bytes.

Targets: each catalogue ≤ 5 minutes on a 2-core machine, Dask within 1.5× of local.
Figures measured while other work runs on the machine are noisy: say so when quoting them.

    .venv/bin/python benchmarks/bench_service.py                   # the full run
    .venv/bin/python benchmarks/bench_service.py --catalogue-n 500 --requests 5   # quick

The first start fits the default model (a minute or two); ``--model-cache DIR`` copies the
cached embedded table and model from a data dir that has them (e.g. ``var``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


class Server:
    """uvicorn in a subprocess on a free loopback port."""

    def __init__(self, data_dir: Path, env_extra: dict[str, str], log: Path) -> None:
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        env = {k: v for k, v in os.environ.items() if not k.startswith("SCENGEN_")}
        env.update({"SCENGEN_DATA_DIR": str(data_dir), **env_extra})
        self._log = open(log, "ab")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "app.main:app", "--host", "127.0.0.1",
             "--port", str(self.port), "--log-level", "warning"],
            cwd=ROOT, env=env, stdout=self._log, stderr=self._log, start_new_session=True)

    def wait(self, timeout: float = 900) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise SystemExit(f"uvicorn exited with {self.proc.returncode}; see the log")
            try:
                if httpx.get(f"{self.base}/health", timeout=5).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.5)
        raise SystemExit("uvicorn did not come up")

    def stop(self) -> None:
        os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self._log.close()


def percentile(values: list[float], p: float) -> float:
    ordered = sorted(values)
    pos = p * (len(ordered) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (pos - lo)


def latency(base: str, n: int, requests: int) -> dict[str, Any]:
    times: list[float] = []
    with httpx.Client(base_url=base, timeout=600) as http:
        for warm in range(2):
            r = http.post("/scenarios", json={"n": n, "seed": 10_000 + warm, "score": True})
            r.raise_for_status()
        for i in range(requests):
            t0 = time.perf_counter()
            r = http.post("/scenarios", json={"n": n, "seed": i, "score": True})
            times.append(time.perf_counter() - t0)
            r.raise_for_status()
            assert len(r.json()["scenarios"]) == n
    return {"n": n, "requests": requests, "p50_s": percentile(times, 0.5),
            "p95_s": percentile(times, 0.95), "mean_s": statistics.fmean(times)}


def catalogue(base: str, n: int, seed: int, chunk_size: int) -> tuple[float, str]:
    with httpx.Client(base_url=base, timeout=600) as http:
        t0 = time.perf_counter()
        r = http.post("/catalogues", json={"n": n, "seed": seed, "score": True,
                                           "chunk_size": chunk_size})
        r.raise_for_status()
        cid = r.json()["id"]
        while True:
            state = http.get(f"/catalogues/{cid}").json()
            if state["status"] in ("done", "failed", "cancelled"):
                break
            time.sleep(0.5)
        elapsed = time.perf_counter() - t0
        if state["status"] != "done":
            raise SystemExit(f"catalogue {cid} {state['status']}: {state['error']}")
        print(f"  catalogue {cid}: {n} scored scenarios in {elapsed:.1f} s, P(A) "
              f"{state['p_region']['estimate']:.3g}", file=sys.stderr)
    return elapsed, cid


def export_csv(base: str, cid: str) -> bytes:
    r = httpx.get(f"{base}/catalogues/{cid}/export", params={"format": "csv"}, timeout=600)
    r.raise_for_status()
    return r.content


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=100, help="n of each POST /scenarios")
    ap.add_argument("--requests", type=int, default=20, help="timed POST /scenarios")
    ap.add_argument("--catalogue-n", type=int, default=10_000)
    ap.add_argument("--chunk-size", type=int, default=250)
    ap.add_argument("--workers", type=int, default=2, help="local pool and Dask workers")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--model-cache", type=Path, default=None,
                    help="data dir whose cached embedded table/model to reuse")
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON")
    ap.add_argument("--keep-exports", type=Path, default=None,
                    help="directory to keep both catalogues' CSV exports in")
    args = ap.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="scengen-bench-"))
    data_dir = work / "data"
    data_dir.mkdir()
    if args.model_cache:
        for sub in ("models", "datasets"):
            if (args.model_cache / sub).is_dir():
                shutil.copytree(args.model_cache / sub, data_dir / sub)
    log = work / "server.log"
    results: dict[str, Any] = {"cpu_count": os.cpu_count(), "catalogue_n": args.catalogue_n,
                               "chunk_size": args.chunk_size, "workers": args.workers}
    try:
        print(f"starting the service (data dir {data_dir}; log {log})", file=sys.stderr)
        server = Server(data_dir, {"SCENGEN_LOCAL_WORKERS": str(args.workers)}, log)
        try:
            server.wait()
            print(f"POST /scenarios n={args.n} with scoring, {args.requests} requests",
                  file=sys.stderr)
            results["scenarios_latency"] = latency(server.base, args.n, args.requests)
            print("catalogue on the local process pool", file=sys.stderr)
            local_s, local_id = catalogue(server.base, args.catalogue_n, args.seed,
                                          args.chunk_size)
            results["catalogue_local_s"] = local_s
            local_csv = export_csv(server.base, local_id)
        finally:
            server.stop()
        if not args.skip_dask:
            from distributed import LocalCluster

            print(f"catalogue on a {args.workers}-worker Dask LocalCluster", file=sys.stderr)
            with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                              dashboard_address=":0", host="127.0.0.1") as cluster:
                server = Server(data_dir, {"SCENGEN_DASK_SCHEDULER": cluster.scheduler_address},
                                log)
                try:
                    server.wait()
                    dask_s, dask_id = catalogue(server.base, args.catalogue_n, args.seed,
                                                args.chunk_size)
                    dask_csv = export_csv(server.base, dask_id)
                finally:
                    server.stop()
            results["catalogue_dask_s"] = dask_s
            results["dask_over_local"] = dask_s / local_s
            results["same_catalogue"] = dask_csv == local_csv
            if args.keep_exports:
                args.keep_exports.mkdir(parents=True, exist_ok=True)
                (args.keep_exports / "local.csv").write_bytes(local_csv)
                (args.keep_exports / "dask.csv").write_bytes(dask_csv)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    text = json.dumps(results, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
