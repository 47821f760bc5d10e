"""Benchmark of the running service over loopback (issues 5 and 13).

Measures, against ``uvicorn app.main:app`` started here in a subprocess:

1. p50 and p95 latency of ``POST /scenarios`` with n = 100 and scoring;
2. the time to build a scored catalogue of ``--catalogue-n`` scenarios (default 10,000)
   on the local process pool (``--workers`` processes), from POST /catalogues to status
   ``done``;
3. the same on a two-worker ``dask.distributed.LocalCluster`` (the service reaches it
   through ``SCENGEN_DASK_SCHEDULER``), and the Dask/local ratio;
4. that both catalogues (same seed) export to the same CSV bytes;
5. ``GET /catalogues/{id}`` (status and statistics) on a stored catalogue of ``--rows``
   rows (default 100,000; hand-made rows written straight into the store);
6. ``/health`` p50/p99 under mixed load (issue 14 item 14): a scored catalogue job of
   ``--health-n`` scenarios running on the pool while ``--readers`` threads page its
   scenarios and poll its status, on SQLite and (``--pg-url``, a fresh database created and
   dropped there) on PostgreSQL.

7. the same catalogue from the command line (``scengen catalogue create`` in a fresh
   process on the same store, the service stopped) and the CLI/HTTP ratio.

``--only status,scenarios,catalogue,cli,health`` runs a subset (default: all).

Before/after (issue 13), measured in the same run, in this process, one core:

* scoring 100 sampled vectors: the old path (build, full Wagner run over every step and
  its summary) against ``sampler.scenario.record.score_vector`` (build + criticality record);
* sampling one catalogue chunk: the old chunk (its own P(B) and a P(A) it threw away)
  against the catalogue-level estimate reused (``sample(known_region=...)``);
* the status statistics of the ``--rows`` catalogue: the old code (every value loaded and
  sorted in Python, kept below as the baseline) against the SQL of
  ``repository.summary_statistics``.

Targets (issue 13): catalogue of 10,000 ≤ 60 s on 2 cores, Dask within 1.2× of local;
POST /scenarios n=100 p50 ≤ 0.5 s; GET /catalogues/{id} at 100,000 rows ≤ 50 ms. The load
average (``/proc/loadavg``) is printed with every figure: figures measured while other
work runs on the machine are noisy, say so when quoting them.

    .venv/bin/python benchmarks/bench_service.py --model-cache var   # the full run
    .venv/bin/python benchmarks/bench_service.py --quick             # 1,000-scenario catalogue

The first start fits the default model (a minute or two); ``--model-cache DIR`` copies the
cached embedded table and model from a data dir that has them (e.g. ``var``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout this script is in, also for in-process parts

from local_service import Server, load, percentile  # noqa: E402


def note(text: str) -> None:
    print(f"{text}  [{load()}]", file=sys.stderr, flush=True)


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
            "p95_s": percentile(times, 0.95), "mean_s": statistics.fmean(times),
            "load": load()}


def cli_catalogue(data_dir: Path, n: int, seed: int, chunk_size: int, workers: int) -> float:
    """Wall clock of ``scengen catalogue create`` (a fresh process, as a user runs it) on
    the service's store: the CLI against the HTTP catalogue (issue 25)."""
    scengen = Path(sys.executable).with_name("scengen")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SCENGEN_")}
    env.update({"SCENGEN_DATA_DIR": str(data_dir), "SCENGEN_LOCAL_WORKERS": str(workers)})
    t0 = time.perf_counter()
    done = subprocess.run([str(scengen), "catalogue", "create", "-n", str(n), "--seed",
                           str(seed), "--chunk-size", str(chunk_size), "-q"], env=env,
                          capture_output=True, text=True, check=False)
    elapsed = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"scengen catalogue create failed: {done.stderr[-2000:]}")
    note(f"  scengen catalogue create: {n} scored scenarios in {elapsed:.1f} s")
    return elapsed


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
        note(f"  catalogue {cid}: {n} scored scenarios in {elapsed:.1f} s, P(A) "
             f"{state['p_region']['estimate']:.3g}")
    return elapsed, cid


def health_under_load(base: str, n: int, seed: int, chunk_size: int,
                      readers: int) -> dict[str, Any]:
    """/health latency while a scored catalogue job runs and ``readers`` threads read."""
    import threading

    with httpx.Client(base_url=base, timeout=600) as http:
        r = http.post("/catalogues", json={"n": n, "seed": seed, "score": True,
                                           "chunk_size": chunk_size})
        r.raise_for_status()
        cid = r.json()["id"]
    done = threading.Event()
    reads = [0]

    def read() -> None:
        with httpx.Client(base_url=base, timeout=600) as http:
            k = 0
            while not done.is_set():
                http.get(f"/catalogues/{cid}/scenarios",
                         params={"limit": 100, "offset": 100 * (k % 5), "order_by": "btn"})
                http.get(f"/catalogues/{cid}")
                reads[0] += 2
                k += 1

    def watch() -> None:
        with httpx.Client(base_url=base, timeout=600) as http:
            while http.get(f"/catalogues/{cid}").json()["status"] not in (
                    "done", "failed", "cancelled"):
                time.sleep(0.5)
        done.set()

    threads = [threading.Thread(target=read, daemon=True) for _ in range(readers)]
    threads.append(threading.Thread(target=watch, daemon=True))
    for t in threads:
        t.start()
    times: list[float] = []
    with httpx.Client(base_url=base, timeout=600) as http:
        while not done.is_set():
            t0 = time.perf_counter()
            http.get("/health").raise_for_status()
            times.append(time.perf_counter() - t0)
            time.sleep(0.05)
    for t in threads:
        t.join(timeout=600)
    return {"catalogue_n": n, "readers": readers, "health_requests": len(times),
            "reads": reads[0], "p50_s": percentile(times, 0.5),
            "p99_s": percentile(times, 0.99), "max_s": max(times), "load": load()}


def pg_fresh_database(admin_url: str) -> tuple[str, Any]:
    """A fresh PostgreSQL database next to ``admin_url``'s: (its URL, a drop function)."""
    import uuid

    import psycopg
    from sqlalchemy.engine import make_url

    url = make_url(admin_url)
    name = f"scengen_bench_{uuid.uuid4().hex[:12]}"
    libpq = url.set(drivername="postgresql").render_as_string(hide_password=False)
    with psycopg.connect(libpq, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')

    def drop() -> None:
        with psycopg.connect(libpq, autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')

    return url.set(database=name).render_as_string(hide_password=False), drop


def store_rows(data_dir: Path, rows: int, chunk: int = 10_000) -> str:
    """A finished catalogue of ``rows`` hand-made rows in the service's store; its id."""
    from app.db import repository as repo
    from app.db.database import Database
    from app.db.models import CatalogueRow, ModelRow

    db = Database(f"sqlite:///{(data_dir / 'scengen.db').resolve()}")
    rng = np.random.default_rng(0)
    with db.session() as s:
        model_id = next(m.id for m in s.query(ModelRow).all() if m.is_default)
        cid = repo.new_id("cat")
        s.add(CatalogueRow(id=cid, model_id=model_id, status="done", n=rows, seed=0,
                           chunk_size=chunk, n_chunks=(rows + chunk - 1) // chunk,
                           spec={"constraints": ["ttc<3"], "method": "auto", "score": True},
                           p_region={"estimate": 0.01, "ci": [0.009, 0.011]}))
    for c in range(0, rows, chunk):
        k = min(chunk, rows - c)
        ttc, risk = rng.exponential(1.5, k), rng.uniform(0, 1, k)
        ttc[::50] = np.inf
        batch = [{"idx": c + i, "chunk_index": c // chunk, "params": {"gap": 10.0, "dv": 5.0},
                  "ttc": float(ttc[i]), "risk": float(risk[i]), "risk_peak": float(risk[i]),
                  "btn": float(risk[i]) * 1.3, "class_": "preventable",
                  "exposure_weight": 0.01 / rows, "summary": {}} for i in range(k)]
        with db.session() as s:
            repo.store_chunk(s, data_dir, cid, c // chunk, batch, None, None, {})
    db.dispose()
    return cid


def status_latency(base: str, cid: str, requests: int) -> dict[str, Any]:
    """p50/p95 of GET /catalogues/{id} (status and statistics)."""
    times: list[float] = []
    with httpx.Client(base_url=base, timeout=600) as http:
        http.get(f"/catalogues/{cid}").raise_for_status()
        for _ in range(requests):
            t0 = time.perf_counter()
            http.get(f"/catalogues/{cid}").raise_for_status()
            times.append(time.perf_counter() - t0)
    return {"requests": requests, "p50_s": percentile(times, 0.5),
            "p95_s": percentile(times, 0.95), "load": load()}


def old_statistics(session: Any, cid: str) -> dict[str, Any]:
    """The baseline: the status statistics as computed before issue 13 (every finite value
    of each column loaded and sorted in Python on every poll)."""
    import math

    from sqlalchemy import select

    from app.db.models import ScenarioRow

    out: dict[str, Any] = {}
    for name, col in (("risk", ScenarioRow.risk), ("ttc", ScenarioRow.ttc),
                      ("exposure_weight", ScenarioRow.exposure_weight)):
        finite = [v for v in session.scalars(select(col).where(
            ScenarioRow.catalogue_id == cid, col.is_not(None)))
            if v is not None and math.isfinite(v)]
        finite.sort()
        k = len(finite)
        out[name] = {"count": k, "p50": finite[(k - 1) // 2], "mean": math.fsum(finite) / k}
    return out


def _best(fn: Any, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def before_after(data_dir: Path, cid: str, chunk_size: int, quick: bool) -> dict[str, Any]:
    """The old and new code paths on the same inputs, in this process (one core)."""
    from app import domain
    from app.db import repository as repo
    from app.db.database import Database
    from app.jobs.chunk import CatalogueSpec, compute_chunk
    from app.jobs.runner import estimate_region
    from riskcore import evaluate_scenario
    from sampler.scenario.builder import build_scenario
    from sampler.scenario.record import score_vector

    out: dict[str, Any] = {}
    model_json = sorted((data_dir / "models").glob("default-*.json"))[0].read_text()
    model = domain.load_model(model_json)
    drawn = domain.sample(model, domain.parse_constraints(["ttc<3"]), 100, 1)
    vectors = [{str(k): float(v) for k, v in r.items()} for r in drawn.params.to_dict("records")]

    def old_scoring() -> None:
        for p in vectors:
            evaluate_scenario(build_scenario(p, seed=1, lane_width=drawn.lane_width)).summary()

    def new_scoring() -> None:
        for p in vectors:
            score_vector(p, lane_width=drawn.lane_width, seed=1)

    old_scoring()  # numba compilation and caches
    new_scoring()
    old_s, new_s = _best(old_scoring, 1 if quick else 2), _best(new_scoring, 1 if quick else 3)
    out["score_100_vectors"] = {"before_s": old_s, "after_s": new_s, "ratio": old_s / new_s,
                                "load": load()}
    note(f"  scoring 100 vectors, one core: before {old_s:.2f} s (build + full Wagner run), "
         f"after {new_s:.2f} s (build + criticality record), x{old_s / new_s:.1f}")

    spec = CatalogueSpec(n=100 * chunk_size, seed=7, chunk_size=chunk_size,
                         model_json=model_json, constraints=("ttc<3",), score=False,
                         store_trajectories=False)
    region = estimate_region(spec)
    reused = CatalogueSpec(**{**spec.to_dict(), "constraints": ("ttc<3",),
                              "p_region": region["estimate"], "region": region})
    compute_chunk(spec, 0)
    old_c = _best(lambda: compute_chunk(spec, 1), 3)
    new_c = _best(lambda: compute_chunk(reused, 1), 3)
    out["sample_chunk"] = {"chunk_size": chunk_size, "before_s": old_c, "after_s": new_c,
                           "ratio": old_c / new_c, "load": load()}
    note(f"  sampling a chunk of {chunk_size} (unscored): before {old_c:.3f} s (own P(B), "
         f"P(A)), after {new_c:.3f} s (catalogue's reused), x{old_c / new_c:.1f}")

    db = Database(f"sqlite:///{(data_dir / 'scengen.db').resolve()}")
    with db.session() as s:
        old_q = _best(lambda: old_statistics(s, cid), 3)
        new_q = _best(lambda: repo.summary_statistics(s, cid), 3)
    db.dispose()
    out["status_statistics"] = {"before_s": old_q, "after_s": new_q, "ratio": old_q / new_q,
                                "load": load()}
    note(f"  status statistics of the stored catalogue: before {old_q * 1e3:.1f} ms "
         f"(Python sort), after {new_q * 1e3:.1f} ms (per-chunk blobs), x{old_q / new_q:.1f}")
    return out


def scenarios_before_after(data_dir: Path, quick: bool) -> dict[str, Any]:
    """The parts of ``POST /scenarios`` n=100 (``ttc<3``) before and after this round, in
    this process (one core): the Wagner alarm/peak scan one ``scene()`` per step (the old
    loop, kept here as the baseline) against the compiled blocks, and sampling with the
    model figures (P(B), the model interval) estimated per request (the memo cleared
    before each) against memoised on the model."""
    from app import domain
    from riskcore.criticality import wagner as criticality
    from sampler.model import memo
    from sampler.scenario.record import score_vector

    def one_scene_per_step(self: Any, ks: Any, level: float, cache: dict[int, float],
                           first_block: int = 8) -> int | None:
        for i, k in enumerate(ks):
            if k not in cache:
                cache[k] = self.scene(float(self.t[k]))[0]
            if cache[k] >= level:
                return i
        return None

    model_json = sorted((data_dir / "models").glob("default-*.json"))[0].read_text()
    model = domain.load_model(model_json)
    ttc3 = domain.parse_constraints(["ttc<3"])
    drawn = domain.sample(model, ttc3, 100, 1)
    vectors = [{str(k): float(v) for k, v in r.items()} for r in drawn.params.to_dict("records")]

    def scoring() -> None:
        for p in vectors:
            score_vector(p, lane_width=drawn.lane_width)

    batched = criticality._Wagner.first_reaching
    scoring()  # compilation
    repeat = 1 if quick else 3
    criticality._Wagner.first_reaching = one_scene_per_step  # type: ignore[method-assign]
    try:
        old_s = _best(scoring, repeat)
    finally:
        criticality._Wagner.first_reaching = batched  # type: ignore[method-assign]
    new_s = _best(scoring, repeat)
    seeds = iter(range(10_000, 20_000))

    def sample_fresh() -> None:
        memo.clear(model)  # as before: every request estimates them
        domain.sample(model, ttc3, 100, next(seeds))

    def sample_memo() -> None:
        domain.sample(model, ttc3, 100, next(seeds))

    old_m, new_m = _best(sample_fresh, repeat), _best(sample_memo, repeat)
    note(f"  scoring 100 ttc<3 vectors, one core: one scene() per step {old_s:.3f} s, "
         f"compiled blocks {new_s:.3f} s, x{old_s / new_s:.2f}")
    note(f"  sampling 100 with P(A), model interval, rates: per request {old_m:.3f} s, "
         f"memoised on the model {new_m:.3f} s, x{old_m / new_m:.1f}")
    return {"score_100": {"before_s": old_s, "after_s": new_s, "ratio": old_s / new_s},
            "sample_100_with_report": {"before_s": old_m, "after_s": new_m,
                                       "ratio": old_m / new_m},
            "load": load()}


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
    ap.add_argument("--rows", type=int, default=100_000,
                    help="rows of the stored catalogue whose status is timed")
    ap.add_argument("--quick", action="store_true",
                    help="a 1,000-scenario catalogue and 5 requests (minutes, not tens)")
    ap.add_argument("--only", default="status,scenarios,catalogue,cli,health",
                    help="comma-separated parts to run: status (with the before/after), "
                         "scenarios, catalogue (local and Dask), health")
    ap.add_argument("--health-n", type=int, default=2000,
                    help="scenarios of the catalogue running while /health is timed")
    ap.add_argument("--readers", type=int, default=4, help="reader threads during it")
    ap.add_argument("--pg-url", default="postgresql+psycopg://postgres@127.0.0.1:5432/test",
                    help="PostgreSQL to time /health on ('' to skip); a fresh database is "
                         "created beside this one and dropped")
    args = ap.parse_args(argv)
    only = set(args.only.split(","))
    if args.quick:
        args.catalogue_n, args.requests = min(args.catalogue_n, 1000), min(args.requests, 5)

    work = Path(tempfile.mkdtemp(prefix="scengen-bench-"))
    data_dir = work / "data"
    data_dir.mkdir()
    if args.model_cache:
        for sub in ("models", "datasets"):
            if (args.model_cache / sub).is_dir():
                shutil.copytree(args.model_cache / sub, data_dir / sub)
    log = work / "server.log"
    results: dict[str, Any] = {"cpu_count": os.cpu_count(), "catalogue_n": args.catalogue_n,
                               "chunk_size": args.chunk_size, "workers": args.workers,
                               "load_at_start": load()}
    try:
        print(f"starting the service (data dir {data_dir}; log {log})", file=sys.stderr)
        server = Server(data_dir, {"SCENGEN_LOCAL_WORKERS": str(args.workers)}, log)
        try:
            server.wait()
            if "status" in only:
                note(f"storing a {args.rows}-row catalogue")
                big = store_rows(data_dir, args.rows)
                note("before/after in this process")
                results["before_after"] = before_after(data_dir, big, args.chunk_size,
                                                       args.quick)
                results["status_latency"] = status_latency(server.base, big, 20)
                note(f"  GET /catalogues/{{id}} at {args.rows} rows: p50 "
                     f"{results['status_latency']['p50_s'] * 1e3:.1f} ms")
            if "scenarios" in only:
                note(f"POST /scenarios n={args.n} with scoring, {args.requests} requests")
                results["scenarios_latency"] = latency(server.base, args.n, args.requests)
                note(f"  p50 {results['scenarios_latency']['p50_s']:.2f} s")
                note("parts of POST /scenarios before/after, in this process")
                results["scenarios_before_after"] = scenarios_before_after(data_dir,
                                                                           args.quick)
            if "health" in only:
                note(f"/health under load (SQLite): a {args.health_n}-scenario job and "
                     f"{args.readers} readers")
                h = health_under_load(server.base, args.health_n, args.seed, args.chunk_size,
                                      args.readers)
                results["health_sqlite"] = h
                note(f"  /health p50 {h['p50_s'] * 1e3:.1f} ms, p99 {h['p99_s'] * 1e3:.1f} ms")
            if "catalogue" in only:
                note("catalogue on the local process pool")
                local_s, local_id = catalogue(server.base, args.catalogue_n, args.seed,
                                              args.chunk_size)
                results["catalogue_local_s"] = local_s
                results["catalogue_local_load"] = load()
                local_csv = export_csv(server.base, local_id)
        finally:
            server.stop()
        if "cli" in only:
            note(f"the same catalogue from the command line (scengen catalogue create, "
                 f"{args.workers} workers, the service stopped)")
            cli_s = cli_catalogue(data_dir, args.catalogue_n, args.seed, args.chunk_size,
                                  args.workers)
            results["catalogue_cli_s"] = cli_s
            results["catalogue_cli_load"] = load()
            if "catalogue_local_s" in results:
                note(f"  CLI / HTTP: {cli_s / results['catalogue_local_s']:.2f}")
        if "health" in only and args.pg_url:
            url, drop = pg_fresh_database(args.pg_url)
            try:
                server = Server(data_dir, {"SCENGEN_LOCAL_WORKERS": str(args.workers),
                                           "SCENGEN_DATABASE_URL": url}, log)
                try:
                    server.wait()
                    note("/health under load (PostgreSQL)")
                    h = health_under_load(server.base, args.health_n, args.seed,
                                          args.chunk_size, args.readers)
                    results["health_postgresql"] = h
                    note(f"  /health p50 {h['p50_s'] * 1e3:.1f} ms, "
                         f"p99 {h['p99_s'] * 1e3:.1f} ms")
                finally:
                    server.stop()
            finally:
                drop()
        if "catalogue" in only and not args.skip_dask:
            from distributed import LocalCluster

            note(f"catalogue on a {args.workers}-worker Dask LocalCluster")
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
            results["catalogue_dask_load"] = load()
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
