"""Thin kinematic bands: ``auto`` (plain Monte Carlo within its budget) against subset-is,
both against a brute force computed here. Asserts nothing.

Regions ``2.9 < ttc < 3 & btn > T`` (``--thresholds``, default 0.4 and 0.5). Brute force:
``--envelope`` exact draws of the TNO model restricted to the ``ttc<3`` envelope; only the
rows inside the band are simulated; P(A and B) = P(S) hits / draws. Then, per threshold:
``--reps`` seeds (100, 101, ...) of ``estimate_p_region`` (``auto``'s path: the extended
pilot, else subset-is) and of ``rare_probability`` (subset-is alone): mean estimate /
reference, spread, share of 95 % intervals (``auto``) or 2-CoV bands (subset-is) covering
the reference, the methods used, seconds per estimate.

Usage: ``.venv/bin/python benchmarks/bench_thin_band.py [--envelope 3e7] [--reps 10]
[--thresholds 0.4,0.5]`` (the brute force takes about a minute per 3e7 draws).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--envelope", type=float, default=3e7)
    parser.add_argument("--reps", type=int, default=10)
    parser.add_argument("--thresholds", default="0.4,0.5")
    args = parser.parse_args()

    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM, estimate_p_region
    from sampler.methods.problem import Problem
    from sampler.methods.rare import rare_probability
    from sampler.region.constraints import Region
    from sampler.region.criticality import criticality_quantities

    model = CutInGMM(random_state=0).fit(default_parameter_table(), source="embedded")
    band = Region.from_constraints(["ttc<3", "ttc>2.9"], lane_width=model.lane_width_)
    problem = Problem(model, band)
    assert problem.envelope is not None
    rng = np.random.default_rng(777)
    n_env, done, parts = int(args.envelope), 0, []
    t = time.perf_counter()
    while done < n_env:
        z = problem.draw_z(min(1 << 20, n_env - done), rng)
        done += z.shape[0]
        x = problem.params(z)
        parts.append(criticality_quantities(x[band.contains(x)], model.lane_width_)["btn"])
    btn = np.concatenate(parts)
    mass = problem.envelope.mass
    print(f"brute force: {n_env:,} envelope draws (P(S) = {mass:.4g}), {btn.size:,} inside "
          f"the band ({btn.size / n_env:.3f}), simulated in {time.perf_counter() - t:.0f} s")
    for thr in (float(s) for s in args.thresholds.split(",")):
        cons = ["ttc<3", "ttc>2.9", f"btn>{thr:g}"]
        k = int((btn > thr).sum())
        ref = mass * k / n_env
        print(f"\n{' & '.join(cons)}: P(A and B) = {ref:.4g} ({k} hits, CoV "
              f"{1 / np.sqrt(max(k, 1)):.3f}), P(btn > {thr:g} | band) = "
              f"{k / max(btn.size, 1):.3g}")
        rows, methods, t = [], set(), time.perf_counter()
        for seed in range(100, 100 + args.reps):
            p = estimate_p_region(model, cons, seed)
            methods.add(p.method)
            rows.append((p.p_joint / ref, p.ci_low <= ref / p.p_bounds <= p.ci_high))
        a = np.array(rows, dtype=float)
        print(f"  auto (estimate_p_region): mean {a[:, 0].mean():.3f}, spread "
              f"{a[:, 0].std(ddof=1):.3f}, intervals covering {a[:, 1].mean():.2f}, "
              f"methods {sorted(methods)}, {(time.perf_counter() - t) / args.reps:.1f} s each",
              flush=True)
        rows, t = [], time.perf_counter()
        for seed in range(100, 100 + args.reps):
            try:
                r = rare_probability(model, cons, seed)
                rows.append((r.probability / ref, abs(r.probability - ref)
                             <= 2 * r.cov * r.probability))
            except ValueError as exc:  # a refusal (LevelsNotConvergedError) counts as a miss
                print(f"    seed {seed}: {str(exc).splitlines()[0][:120]}")
                rows.append((np.nan, False))
        a = np.array(rows, dtype=float)
        print(f"  subset-is (rare_probability): mean {np.nanmean(a[:, 0]):.3f}, spread "
              f"{np.nanstd(a[:, 0], ddof=1):.3f}, range {np.nanmin(a[:, 0]):.2f}-"
              f"{np.nanmax(a[:, 0]):.2f}, inside 2 CoV {a[:, 1].mean():.2f}, "
              f"{(time.perf_counter() - t) / args.reps:.1f} s each", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
