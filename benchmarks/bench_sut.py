"""Runs per second per core of the closed-loop simulator (riskcore.sut) for built-in SUTs.

Two batches: (a) generated cut-ins (sampler's build_scenario) from uniform draws of the
parameter vector over typical highway ranges (about half of them closing with TTC < 3 s
at the crossing), tiled to ``--runs`` runs; (b) ``--model-draws`` vectors drawn from the
embedded TNO model (the distribution a naive Monte-Carlo campaign simulates; rows the
builder refuses are left out), via ``sampler.scenario.cutin_batch``. Every thread pool
is pinned to one thread, so the figures are per core; runs/s are taken over the process's
CPU time (the machine is shared: wall-clock figures are printed beside them).

Per SUT and step: the compiled loop ``engine="fused"`` (the default) against the
previous implementation ``engine="stepwise"`` measured in the same run on the same runs
(the ratio is printed), whether their outcomes are bit-identical (all fields), and
whether both equal the Python step loop ``engine="loop"`` (on a slice). For idm and acc,
also the same SUT written as a plain per-run class behind :func:`riskcore.sut.per_run`.
Issue 24 asks >= 20,000 built-in runs per second per core at dt = 0.01 s.

(c) The campaign's runner (``sampler.campaign.sut_runner``, acc, careful=False) end to
end from in-bounds model draws to outcomes, in blocks of ``--runner-blocks`` rows, against
its previous path (the same with the builder's previous rule: the lateral motion by the
trapezoid on 1 ms steps instead of Gauss-Legendre on 0.1 s panels) on the same blocks,
with the share of the track builder (and of the previous rule's) and the share of runs
equal field for field and the largest relative difference (the rules differ in the
positions' low bits, about 5e-6 m at most). It also splits the runner's CPU time per run
into the tracks (``buildable_batches``), the simulation (``simulate`` on the same batches
built beforehand) and the rest (assembling the outcomes, Python between the calls), each
the least of ``--runner-repeats`` interleaved passes.

Usage (from the repository root): ``PYTHONPATH=. .venv/bin/python benchmarks/bench_sut.py
[--runs 20000] [--scenarios 400] [--model-draws 5000] [--baseline 200] [--seed 7]
[--dt 0.01 0.05] [--runner-draws 16384] [--runner-blocks 256 1024 4096 16384]
[--runner-repeats 3] [--only-runner]``
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
    RunBatch,
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


def _bytes(r: RunBatch) -> bytes:
    return b"".join(np.ascontiguousarray(getattr(r, k)).tobytes() for k in RunBatch.FIELDS)


def model_batch(n: int, seed: int) -> CutInBatch:
    """n buildable vectors drawn from the embedded TNO model (the campaign's model)."""
    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM
    from sampler.scenario.batch import cutin_batch, cutin_tracks

    model = CutInGMM().fit(default_parameter_table())
    rng = np.random.default_rng(seed)
    rows: list[np.ndarray] = []
    got = 0
    while got < n:
        x = model.params_matrix(model.sample(2 * n, rng))
        ok = cutin_tracks(x).ok
        rows.append(x[ok])
        got += int(ok.sum())
    return cutin_batch(np.concatenate(rows)[:n])


def timed(sut_name: str, batch: CutInBatch, st: SimSettings, seed: int,
          engine: str) -> tuple[RunBatch, float, float]:
    """(runs, CPU seconds, wall seconds)."""
    c, w = time.process_time(), time.perf_counter()
    runs = simulate(make_sut(sut_name), batch, seeds=seed, settings=st, engine=engine)
    return runs, time.process_time() - c, time.perf_counter() - w


def compare_engines(label: str, batch: CutInBatch, st: SimSettings, seed: int,
                    names: tuple[str, ...], loop_n: int) -> dict[str, float]:
    """Print the fused and stepwise rates and their equality; returns fused runs/s."""
    rates = {}
    for name in names:
        small = batch.subset(np.arange(min(8, batch.n)))
        for eng in ("fused", "stepwise"):
            simulate(make_sut(name), small, seeds=0, settings=st, engine=eng)  # compile
        fused, cpu_f, wall_f = timed(name, batch, st, seed, "fused")
        step, cpu_s, wall_s = timed(name, batch, st, seed, "stepwise")
        sub = batch.subset(np.arange(min(loop_n, batch.n)))
        loop = simulate(make_sut(name), sub, seeds=seed, settings=st, engine="loop")
        fused_sub = simulate(make_sut(name), sub, seeds=seed, settings=st)
        rate = batch.n / cpu_f
        rates[name] = rate
        steps = float(np.nanmean(fused.end_time)) / st.dt
        print(f"  {label}, dt {st.dt} s, {name:8s}: fused {rate:9,.0f} runs/s per core "
              f"(wall {batch.n / wall_f:,.0f}); stepwise (previous) {batch.n / cpu_s:8,.0f} "
              f"runs/s (wall {batch.n / wall_s:,.0f}) -> {cpu_s / cpu_f:.1f}x; "
              f"{steps:.0f} steps/run, {int(fused.collided.sum())}/{batch.n} collide; "
              f"bit-identical to stepwise: {_bytes(fused) == _bytes(step)}, "
              f"to the Python loop ({sub.n} runs): {_bytes(fused_sub) == _bytes(loop)}; "
              f"20,000 target {'met' if rate >= 20_000 else 'NOT met'}")
    return rates


def runner_draws(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """n in-bounds draws of the embedded TNO model (what naive Monte Carlo feeds the
    campaign's runner: ``region.in_bounds``, some still refused by the builder), their
    seeds and the CPU seconds per draw of drawing them."""
    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM
    from sampler.region import Region

    model = CutInGMM().fit(default_parameter_table())
    rng = np.random.default_rng(seed)
    region = Region.from_constraints((), lane_width=model.lane_width_).bind(model)
    c = time.process_time()
    x = model.params_matrix(model.from_z(model.sample_z(2 * n, rng)))
    x = x[region.in_bounds(x)][:n]
    draw = (time.process_time() - c) / x.shape[0]
    seeds = np.asarray(rng.integers(0, 2**63, size=x.shape[0], dtype=np.uint64))
    return x, seeds, draw


def runner_previous(x: np.ndarray, seeds: np.ndarray, st: SimSettings,
                    lane: float) -> tuple[np.ndarray, np.ndarray, RunBatch]:
    """The campaign runner's path with the builder's previous rule (``quadrature=
    "trapezoid"``: the lateral motion on 1 ms steps): each row on its own grid
    (``buildable_batches``), simulate. Returns (collided of every row, the buildable rows,
    their runs)."""
    from sampler.scenario.batch import buildable_batches

    _, groups = buildable_batches(x, lane_width=lane, quadrature="trapezoid")
    parts = [(rows, simulate(make_sut("acc", k2=0.5), batch, seeds=seeds[rows],
                             settings=st)) for rows, batch in groups]
    rows = np.concatenate([r for r, _ in parts])
    order = np.argsort(rows)
    runs = RunBatch.concat([r for _, r in parts]).subset(order)
    collided = np.zeros(x.shape[0], dtype=bool)
    collided[rows[order]] = runs.collided
    return collided, rows[order], runs


def bench_runner(n: int, seed: int, blocks: list[int], repeats: int = 3) -> None:
    """(c) ``sampler.campaign.sut_runner`` end to end (acc k2=0.5, careful=False, t_max
    40 s, collisions only) on model draws, in blocks of each size, against the previous
    path on the same blocks; all fields compared (``_agreement``). The runner and its
    stages are timed ``repeats`` times, interleaved, and the least CPU time of each is
    reported (the machine is shared: the least is the one least disturbed)."""
    from sampler.campaign import sut_runner
    from sampler.scenario.batch import buildable_batches

    lane = 3.75
    st = SimSettings(t_max=40.0)
    x, seeds, draw = runner_draws(n, seed)
    runner = sut_runner(lambda: make_sut("acc", k2=0.5), careful=False, settings=st,
                        lane_width=lane, name="acc")
    runner(x[:64], seeds[:64])  # compile
    runner_previous(x[:64], seeds[:64], st, lane)
    print(f"(c) campaign runner end to end, acc k2=0.5, t_max {st.t_max} s, careful=False: "
          f"{x.shape[0]} in-bounds model draws (drawing them: {draw * 1e6:.1f} us CPU per "
          f"draw, not in the figures below); least CPU time of {repeats} passes")
    m = x.shape[0]
    for b in blocks:
        new, t_new, t_build, t_sim = _runner_stages(runner, x, seeds, b, st, lane, repeats)
        c = time.process_time()
        old = [runner_previous(x[i:i + b], seeds[i:i + b], st, lane)
               for i in range(0, x.shape[0], b)]
        t_old = time.process_time() - c
        c = time.process_time()
        for i in range(0, x.shape[0], b):
            buildable_batches(x[i:i + b], lane_width=lane, quadrature="trapezoid")
        t_build_old = time.process_time() - c
        agree, worst = _agreement(new, old)
        print(f"  blocks of {b:6d}: runner {m / t_new:8,.0f} runs/s per core (CPU); previous "
              f"path {m / t_old:8,.0f} runs/s -> {t_old / t_new:.2f}x; of the runner's time "
              f"{t_build / t_new:.0%} builds the tracks ({m / t_build:,.0f} rows/s; "
              f"previous rule {m / t_build_old:,.0f} rows/s, {t_build_old / t_old:.0%} of "
              "its path); "
              f"{sum(int(r.collided.sum()) for r in new)} collisions; runs with every "
              f"field bit-identical to the previous path: {agree:.1%}, largest difference "
              f"of a float field {worst:.1e} (relative)")
        print(f"    per run (CPU): {t_new / m * 1e6:.1f} us = tracks (buildable_batches) "
              f"{t_build / m * 1e6:.1f} us + simulation (simulate on the built batches) "
              f"{t_sim / m * 1e6:.1f} us + the rest (assembling the outcomes, Python "
              f"between the calls) {(t_new - t_build - t_sim) / m * 1e6:.1f} us; 20,000 "
              f"runs/s per core {'met' if m / t_new >= 20_000 else 'NOT met'}")


def _runner_stages(runner: object, x: np.ndarray, seeds: np.ndarray, b: int,
                   st: SimSettings, lane: float, repeats: int
                   ) -> tuple[list, float, float, float]:
    """(the runner's outcomes per block, and the least CPU seconds over ``repeats``
    interleaved passes of: the runner, its tracks alone (``buildable_batches``), its
    simulation alone (``simulate`` on batches built beforehand))."""
    from sampler.scenario.batch import buildable_batches

    starts = range(0, x.shape[0], b)
    built = [(i, buildable_batches(x[i:i + b], lane_width=lane)[1]) for i in starts]
    t_new = t_build = t_sim = math.inf
    new: list = []
    for _ in range(max(repeats, 1)):
        c = time.process_time()
        new = [runner(x[i:i + b], seeds[i:i + b]) for i in starts]  # type: ignore[operator]
        t_new = min(t_new, time.process_time() - c)
        c = time.process_time()
        for i in starts:
            buildable_batches(x[i:i + b], lane_width=lane)
        t_build = min(t_build, time.process_time() - c)
        c = time.process_time()
        for i, groups in built:
            for rows, batch in groups:
                simulate(make_sut("acc", k2=0.5), batch, seeds=seeds[i:i + b][rows],
                         settings=st)
        t_sim = min(t_sim, time.process_time() - c)
    return new, t_new, t_build, t_sim


def _agreement(new: list, old: list) -> tuple[float, float]:
    """(share of runs whose every field is bit-identical, largest relative difference of
    a float field) between the runner and the previous path."""
    from riskcore.sut import RUN_FIELDS

    same = 0
    total = 0
    worst = 0.0
    for r, (collided, rows, runs) in zip(new, old, strict=True):
        ok = np.asarray(r.collided) == collided
        ok = ok[rows]
        for f, spec in RUN_FIELDS.items():
            a = np.asarray(getattr(r, f))[rows]
            b = np.asarray(getattr(runs, f))
            if spec.kind == "float":
                eq = (a == b) | (np.isnan(a) & np.isnan(b))
                both = np.isfinite(a) & np.isfinite(b)
                if both.any():
                    rel = np.abs(a[both] - b[both]) / np.maximum(np.abs(b[both]), 1e-12)
                    worst = max(worst, float(rel.max()))
            else:
                eq = a == b
            ok &= eq
        same += int(ok.sum())
        total += rows.size
    return same / max(total, 1), worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20_000)
    ap.add_argument("--scenarios", type=int, default=400)
    ap.add_argument("--model-draws", type=int, default=5_000)
    ap.add_argument("--baseline", type=int, default=200)
    ap.add_argument("--loop", type=int, default=400,
                    help="runs compared with the Python step loop")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--dt", type=float, nargs="+", default=[0.01, 0.05],
                    help="simulation steps to measure (s; 0.01 is the default setting)")
    ap.add_argument("--runner-draws", type=int, default=16_384,
                    help="model draws of the campaign runner's end-to-end figure (c)")
    ap.add_argument("--runner-blocks", type=int, nargs="+", default=[256, 1024, 4096, 16384],
                    help="rows per runner call in (c)")
    ap.add_argument("--runner-repeats", type=int, default=3,
                    help="passes of (c)'s runner and stages (the least CPU time is shown)")
    ap.add_argument("--only-runner", action="store_true", help="only (c)")
    args = ap.parse_args()
    if args.runner_draws > 0:
        print(f"load average before: {os.getloadavg()[0]:.1f} (2-core machine shared)")
        bench_runner(args.runner_draws, args.seed, args.runner_blocks, args.runner_repeats)
        if args.only_runner:
            print(f"load average after: {os.getloadavg()[0]:.1f}")
            return
    t0 = time.perf_counter()
    scs = scenarios(args.scenarios, args.seed)
    base = CutInBatch.from_scenarios(scs)
    idx = np.arange(args.runs) % base.n
    batch = base.subset(idx)
    print(f"(a) uniform batch: {batch.n} runs ({base.n} distinct cut-ins, grid "
          f"{batch.t.size} x {batch.dt} s), built in {time.perf_counter() - t0:.1f} s")
    mb = None
    if args.model_draws > 0:
        t0 = time.perf_counter()
        mb = model_batch(args.model_draws, args.seed)
        print(f"(b) model batch: {mb.n} draws of the embedded TNO model (grid {mb.t.size} x "
              f"{mb.dt} s), fitted and built in {time.perf_counter() - t0:.1f} s")
    print(f"load average before: {os.getloadavg()[0]:.1f} (2-core machine shared)")
    names = ("none", "idm", "acc", "acc_aeb")
    for dt in args.dt:
        st = SimSettings(dt=dt)
        rates = compare_engines("(a)", batch, st, args.seed, names, args.loop)
        if mb is not None:
            compare_engines("(b)", mb, st, args.seed, names, args.loop)
        for name, plain in (("idm", PlainIDM), ("acc", PlainACC)):
            simulate(per_run(plain, "warm"), base.subset(np.arange(2)), seeds=0, settings=st)
            sub = base.subset(np.arange(min(args.baseline, base.n)))
            c = time.process_time()
            ref = simulate(per_run(plain, f"plain_{name}"), sub, seeds=args.seed, settings=st)
            rate_b = sub.n / (time.process_time() - c)
            fast_sub = simulate(make_sut(name), sub, seeds=args.seed, settings=st)
            same = bool(np.array_equal(fast_sub.collided, ref.collided) and np.allclose(
                fast_sub.impact_speed, ref.impact_speed, atol=1e-9))
            print(f"  (a), dt {dt} s, {name}: per-run adapter (plain class) {rate_b:,.1f} "
                  f"runs/s ({sub.n} runs) -> fused is {rates[name] / rate_b:,.0f}x; same "
                  f"outcomes: {same}")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
