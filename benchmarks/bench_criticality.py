"""Benchmark of the criticality record (issue 11). Prints figures; asserts nothing.

Run: .venv/bin/python benchmarks/bench_criticality.py [--n 300] [--vectors 1000]
     [--samples 1000] [--repeat 3] [--skip 1,3]

Vectors: the README catalogue's draw (the default model fitted on the embedded TNO table,
``ttc<3``, seed 7). Figures, each on one core in CPU time of this process (less disturbed
by other jobs than wall time; wall time printed beside it) with ``uptime``'s load:

1. ``evaluate_criticality`` per generated cut-in (the scenario-level record; budget
   ~5 ms), beside riskcore's ``evaluate_scenario`` of the same scenarios (the baseline:
   the old per-step risk) and the builder.
2. ``criticality_quantities`` (sampler level) in vectors/s for the driver-model quantities
   (no TTR scan; target: >= 50,000 vectors/s on one core), before (``baseline=True``: every
   0.01 s step of the simulation grid) and after (the pruned kernels) in the same run,
   with the largest difference between the two; then with the TTR scan.
3. ``sample(model, ["ttc<3", "btn>0.7", "btn<1"], n=--samples)`` end to end (target:
   1,000 samples in <= 10 s).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from datasets.cutin_model import PARAM_NAMES  # noqa: E402
from datasets.embedded import default_parameter_table  # noqa: E402
from riskcore import evaluate_scenario  # noqa: E402
from riskcore.criticality import evaluate_criticality  # noqa: E402
from sampler import CutInGMM, build_scenario, sample  # noqa: E402
from sampler.region.criticality import criticality_quantities  # noqa: E402


def load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


def timed(fn):  # type: ignore[no-untyped-def]
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.process_time() - c, time.perf_counter() - w


def best_of(n, fn):  # type: ignore[no-untyped-def]
    """The fastest of n runs (CPU time), with its wall time."""
    best = None
    for _ in range(n):
        run = timed(fn)
        if best is None or run[1] < best[1]:
            best = run
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=300, help="scenarios for figure 1")
    ap.add_argument("--vectors", type=int, default=1000, help="vectors for figure 2")
    ap.add_argument("--samples", type=int, default=1000, help="samples for figure 3")
    ap.add_argument("--repeat", type=int, default=3, help="runs of figure 2 (best kept)")
    ap.add_argument("--skip", default="", help="figures to skip, e.g. '1,3'")
    args = ap.parse_args()
    print("load:", load())
    model = CutInGMM(random_state=0).fit(default_parameter_table())
    ss = sample(model, ["ttc<3"], n=max(args.n, args.vectors), seed=7)
    lw = float(ss.region.lane_width)
    params = np.asarray(ss.params[list(PARAM_NAMES)] if hasattr(ss.params, "columns")
                        else ss.params, dtype=float)

    skip = {x.strip() for x in args.skip.split(",") if x.strip()}
    if "1" not in skip:
        scenario_level(params, lw, args.n)
    if "2" not in skip:
        sampler_level(params, lw, args)
    if "3" not in skip:
        print("load:", load())
        out, cpu_s, wall_s = timed(lambda: sample(model, ["ttc<3", "btn>0.7", "btn<1"],
                                                  n=args.samples, seed=7))
        print(f"3. sample(ttc<3 & btn>0.7 & btn<1, n={args.samples}): {wall_s:.1f} s wall, "
              f"{cpu_s:.1f} s CPU (target <= 10 s); method {out.method}")
    print("load:", load())


def scenario_level(params: np.ndarray, lw: float, n: int) -> None:
    """Figure 1: the scenario-level record per generated cut-in."""
    rows = params[:n]
    scen, cpu_b, _ = timed(lambda: [build_scenario(dict(zip(PARAM_NAMES, r, strict=True)),
                                                   lane_width=lw) for r in rows])
    evaluate_criticality(scen[0])
    recs, cpu_c, wall_c = timed(lambda: [evaluate_criticality(s) for s in scen])
    n_r = min(100, n)
    _, cpu_r, _ = timed(lambda: [evaluate_scenario(s) for s in scen[:n_r]])
    print(f"1. evaluate_criticality: {cpu_c / n * 1e3:.2f} ms CPU per cut-in "
          f"({wall_c / n * 1e3:.2f} ms wall), n = {n}; build_scenario "
          f"{cpu_b / n * 1e3:.2f} ms; baseline evaluate_scenario "
          f"{cpu_r / n_r * 1e3:.2f} ms (ratio {cpu_r / n_r / (cpu_c / n):.1f}x)")
    classes: dict[str, int] = {}
    for r in recs:
        classes[r.category] = classes.get(r.category, 0) + 1
    print("   classes:", classes)


def sampler_level(params: np.ndarray, lw: float, args: argparse.Namespace) -> None:
    """Figure 2: the fast path and the baseline (grid) path, same vectors, same run."""
    vec = params[: args.vectors]
    for baseline in (True, False):
        criticality_quantities(vec[:5], lw, with_ttr=False, baseline=baseline)
    print("load:", load())
    q_grid, cpu_g, wall_g = best_of(args.repeat, lambda: criticality_quantities(
        vec, lw, with_ttr=False, baseline=True))
    q_fast, cpu_v, wall_v = best_of(args.repeat, lambda: criticality_quantities(
        vec, lw, with_ttr=False))
    _, cpu_t, wall_t = timed(lambda: criticality_quantities(vec, lw))
    worst = 0.0
    for name in ("t_p", "a_req", "btn", "r157_collision", "r157_impact_speed",
                 "none_collision"):
        a, b = q_fast[name], q_grid[name]
        both = np.isfinite(a) & np.isfinite(b)
        if not np.array_equal(np.isfinite(a), np.isfinite(b)):
            worst = math.inf
        elif both.any():
            worst = max(worst, float(np.max(np.abs(a[both] - b[both]))))
    print(f"2. criticality_quantities, driver-model quantities (t_p, a_req, btn, R157 and "
          f"constant-speed outcomes), n = {len(vec)}, best of {args.repeat}:\n"
          f"   before (baseline=True, every 0.01 s step): {len(vec) / cpu_g:,.0f} "
          f"vectors/s CPU ({len(vec) / wall_g:,.0f} wall)\n"
          f"   after  (pruned kernels):                  {len(vec) / cpu_v:,.0f} "
          f"vectors/s CPU ({len(vec) / wall_v:,.0f} wall); speed-up "
          f"{cpu_g / cpu_v:.1f}x; largest difference {worst:.1e} (target 50,000/s)\n"
          f"   with ttr_true: {len(vec) / cpu_t:,.0f} vectors/s CPU "
          f"({len(vec) / wall_t:,.0f} wall)")
    classes = {"no_conflict": int(np.sum(q_fast["none_collision"] == 0)),
               "preventable": int(np.sum((q_fast["none_collision"] == 1)
                                         & (q_fast["r157_collision"] == 0))),
               "r157_collides": int(np.sum(q_fast["r157_collision"] == 1))}
    print("   the same vectors by the sampler-level quantities:", classes)


if __name__ == "__main__":
    main()
