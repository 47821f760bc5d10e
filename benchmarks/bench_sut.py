"""Runs per second per core of the closed-loop simulator (riskcore.sut) for built-in SUTs.

A realistic batch: generated cut-ins (sampler's build_scenario) from uniform draws of the
parameter vector over typical highway ranges (about half of them closing with TTC < 3 s at
the crossing), tiled to ``--runs`` runs. Every thread pool is pinned to one thread, so the
figures are per core. Baseline in the same run: the same SUT written as a plain per-run
class behind :func:`riskcore.sut.per_run` (a Python call per run and step) on a slice of
the batch; the ratio is printed. Issue 24 asks >= 20,000 built-in runs per second per core.

Usage (from the repository root): ``PYTHONPATH=. .venv/bin/python benchmarks/bench_sut.py
[--runs 20000] [--scenarios 400] [--baseline 200] [--seed 7]``
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
             "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from riskcore.scenario import ConcreteScenario  # noqa: E402
from riskcore.sut import (  # noqa: E402
    CutInBatch,
    Observation,
    SimSettings,
    make_sut,
    per_run,
    simulate,
)
from sampler import BuilderError, build_scenario  # noqa: E402


def scenarios(n: int, seed: int) -> list[ConcreteScenario]:
    rng = np.random.default_rng(seed)
    out: list[ConcreteScenario] = []
    while len(out) < n:
        dv = rng.uniform(-2.0, 10.0)
        p = {"p_y1": rng.choice([-1, 1]) * rng.uniform(0.05, 0.2),
             "p_t": rng.uniform(1.5, 3.0), "p_a1": rng.uniform(-3.0, 1.0),
             "p_a2": rng.uniform(-1.0, 3.0), "p_a3": rng.uniform(0.0, 3.0),
             "p_v0": rng.uniform(15.0, 35.0), "dv": dv, "gap": rng.uniform(2.0, 40.0)}
        try:
            out.append(build_scenario(p))
        except BuilderError:
            continue
    return out


class PlainIDM:
    def reset(self, seed: int) -> None:
        self.v0: float | None = None

    def act(self, obs: Observation) -> float:
        if self.v0 is None:
            self.v0 = max(obs.ego_v, 0.1)
        v = obs.ego_v
        free = 1.0 - (v / self.v0) ** 4.0
        if obs.present[0] and obs.lane[0] == 0 and obs.dx[0] > 0:
            s = max(float(obs.gap[0]), 0.01)
            s_star = 2.0 + max(0.0, v * 1.6 + v * (v - obs.vx[0]) / (2 * math.sqrt(0.73 * 1.67)))
            return 0.73 * (free - (s_star / s) ** 2)
        return 0.73 * free


class PlainACC:
    def reset(self, seed: int) -> None:
        self.v_set: float | None = None

    def act(self, obs: Observation) -> float:
        if self.v_set is None:
            self.v_set = obs.ego_v
        v = obs.ego_v
        cruise = 0.4 * (self.v_set - v)
        cmd = cruise
        if obs.present[0] and obs.lane[0] == 0 and obs.dx[0] > 0 and obs.gap[0] <= 120:
            cmd = min(cruise, 0.23 * (obs.gap[0] - 2.0 - 1.1 * v) + 0.07 * (obs.vx[0] - v))
        return float(min(max(cmd, -6.0), 2.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20_000)
    ap.add_argument("--scenarios", type=int, default=400)
    ap.add_argument("--baseline", type=int, default=200)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--dt", type=float, nargs="+", default=[0.01, 0.05],
                    help="simulation steps to measure (s; 0.01 is the default setting)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    scs = scenarios(args.scenarios, args.seed)
    base = CutInBatch.from_scenarios(scs)
    idx = np.arange(args.runs) % base.n
    batch = base.subset(idx)
    print(f"batch: {batch.n} runs ({base.n} distinct cut-ins, grid {batch.t.size} x "
          f"{batch.dt} s), built in {time.perf_counter() - t0:.1f} s")
    small = base.subset(np.arange(min(8, base.n)))
    print(f"load average before: {os.getloadavg()[0]:.1f} (2-core machine shared)")
    for dt in args.dt:
        st = SimSettings(dt=dt)
        for name, plain in (("idm", PlainIDM), ("acc", PlainACC)):
            simulate(make_sut(name), small, seeds=0, settings=st)  # compile / warm
            simulate(per_run(plain, "warm"), small.subset(np.arange(2)), seeds=0, settings=st)
            t = time.perf_counter()
            runs = simulate(make_sut(name), batch, seeds=args.seed, settings=st)
            wall = time.perf_counter() - t
            rate = batch.n / wall
            sub = base.subset(np.arange(min(args.baseline, base.n)))
            t = time.perf_counter()
            ref = simulate(per_run(plain, f"plain_{name}"), sub, seeds=args.seed, settings=st)
            wall_b = time.perf_counter() - t
            rate_b = sub.n / wall_b
            fast_sub = simulate(make_sut(name), sub, seeds=args.seed, settings=st)
            same = bool(np.array_equal(fast_sub.collided, ref.collided) and np.allclose(
                fast_sub.impact_speed, ref.impact_speed, atol=1e-9))
            steps = float(np.nanmean(runs.end_time)) / dt
            print(f"dt {dt} s, {name}: {rate:,.0f} runs/s per core ({wall:.2f} s for "
                  f"{batch.n}; mean {steps:.0f} steps per run; collisions "
                  f"{int(runs.collided.sum())}); per-run adapter {rate_b:,.1f} runs/s "
                  f"({sub.n} runs) -> {rate / rate_b:,.0f}x; same outcomes: {same}; "
                  f"target 20,000: {'met' if rate >= 20_000 else 'NOT met'}; load "
                  f"{os.getloadavg()[0]:.1f}")

if __name__ == "__main__":
    main()
