"""Benchmark of the criticality record (issue 11). Prints figures; asserts nothing.

Run: .venv/bin/python benchmarks/bench_criticality.py [--n 1000] [--samples 1000]

Vectors: the README catalogue's draw (the default model fitted on the embedded TNO table,
``ttc<3``, seed 7). Figures, each on one core in CPU time of this process (less disturbed
by other jobs than wall time; wall time printed beside it) with ``uptime``'s load:

1. ``evaluate_criticality`` per generated cut-in (the scenario-level record; budget
   ~5 ms), beside riskcore's ``evaluate_scenario`` of the same scenarios (the baseline:
   the old per-step risk) and the builder.
2. ``criticality_quantities`` (sampler level) in vectors/s, with and without the TTR scan
   (target: >= 50,000 vectors/s for the driver-model quantities).
3. ``sample(model, ["ttc<3", "btn>0.7", "btn<1"], n=--samples)`` end to end (target:
   1,000 samples in <= 10 s).
"""

from __future__ import annotations

import argparse
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
from sampler.criticality import criticality_quantities  # noqa: E402


def load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


def timed(fn):  # type: ignore[no-untyped-def]
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.process_time() - c, time.perf_counter() - w


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=300, help="scenarios for figure 1")
    ap.add_argument("--vectors", type=int, default=1000, help="vectors for figure 2")
    ap.add_argument("--samples", type=int, default=1000, help="samples for figure 3")
    args = ap.parse_args()
    print("load:", load())
    model = CutInGMM(random_state=0).fit(default_parameter_table())
    ss = sample(model, ["ttc<3"], n=max(args.n, args.vectors), seed=7)
    lw = float(ss.region.lane_width)
    params = np.asarray(ss.params[list(PARAM_NAMES)] if hasattr(ss.params, "columns")
                        else ss.params, dtype=float)

    # 1. scenario level
    rows = params[: args.n]
    scen, cpu_b, _ = timed(lambda: [build_scenario(dict(zip(PARAM_NAMES, r, strict=True)),
                                                   lane_width=lw) for r in rows])
    evaluate_criticality(scen[0])
    recs, cpu_c, wall_c = timed(lambda: [evaluate_criticality(s) for s in scen])
    _, cpu_r, _ = timed(lambda: [evaluate_scenario(s) for s in scen[: min(100, args.n)]])
    n_r = min(100, args.n)
    print(f"1. evaluate_criticality: {cpu_c / args.n * 1e3:.2f} ms CPU per cut-in "
          f"({wall_c / args.n * 1e3:.2f} ms wall), n = {args.n}; build_scenario "
          f"{cpu_b / args.n * 1e3:.2f} ms; baseline evaluate_scenario "
          f"{cpu_r / n_r * 1e3:.2f} ms (ratio {cpu_r / n_r / (cpu_c / args.n):.1f}x)")
    classes: dict[str, int] = {}
    for r in recs:
        classes[r.category] = classes.get(r.category, 0) + 1
    print("   classes:", classes)

    # 2. sampler level
    vec = params[: args.vectors]
    criticality_quantities(vec[:5], lw)
    _, cpu_v, wall_v = timed(lambda: criticality_quantities(vec, lw, with_ttr=False))
    _, cpu_t, wall_t = timed(lambda: criticality_quantities(vec, lw))
    print(f"2. criticality_quantities: {len(vec) / cpu_v:,.0f} vectors/s CPU "
          f"({len(vec) / wall_v:,.0f} wall) for t_p, a_req, btn, R157 outcome; "
          f"{len(vec) / cpu_t:,.0f} vectors/s CPU ({len(vec) / wall_t:,.0f} wall) with "
          "ttr_true (target 50,000/s for the driver-model quantities)")

    # 3. sampling from the criticality constraints
    print("load:", load())
    out, cpu_s, wall_s = timed(lambda: sample(model, ["ttc<3", "btn>0.7", "btn<1"],
                                              n=args.samples, seed=7))
    print(f"3. sample(ttc<3 & btn>0.7 & btn<1, n={args.samples}): {wall_s:.1f} s wall, "
          f"{cpu_s:.1f} s CPU (target <= 10 s); method {out.method}")
    print("load:", load())


if __name__ == "__main__":
    main()
