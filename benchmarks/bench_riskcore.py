"""Benchmark of the riskcore engine (issue 2). Prints figures; asserts nothing about time.

Run: .venv/bin/python benchmarks/bench_riskcore.py

Settings of Table II (horizon 3 s, dt 0.1 s, 10 x 10 samples). The scene is the paper's
parallel cut-in (Fig. 3-5) with fixed input distributions (μ_a = 0.9, σ_a = 0.62 m/s²,
μ_ω = -0.09, σ_ω = 0.04 rad/s), where most predicted trajectories collide. Timings are
medians of repeated runs on one core (numba kernels are compiled, or loaded from the
cache, before timing); on a shared machine they are noisy.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from riskcore import (  # noqa: E402
    ConcreteScenario,
    EgoFuture,
    InputSurfaces,
    ObjectState,
    RiskSettings,
    Track,
    evaluate_scenario,
    evaluate_scene,
)
from tests.riskcore.reference import RefObject, RefSettings, ref_object  # noqa: E402

MEAN_A, STD_A, MEAN_W, STD_W = 0.9, 0.62, -0.09, 0.04


def constant_surfaces() -> InputSurfaces:
    def one(mean: float, std: float) -> dict[str, object]:
        return {"v0": [0.0], "x0": [0.0], "mean": [[mean]], "std": [[std]]}
    return InputSurfaces.from_dict({"format": "scengen.input-surfaces/1", "interim": True,
                                    "source": "benchmark", "accel": one(MEAN_A, STD_A),
                                    "turn": one(MEAN_W, STD_W)})


def median_time(fn: Callable[[], object], repeat: int, number: int = 1) -> float:
    """Median over ``repeat`` runs of the CPU time of this process for ``number`` calls,
    per call, in s (process time: less disturbed by other jobs than wall time)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(number):
            fn()
        times.append((time.process_time() - t0) / number)
    return statistics.median(times)


def cut_in_scenario(x0: float = 22.0, v_cut: float = 24.0) -> ConcreteScenario:
    """10 s at 10 Hz: ego at 25 m/s; a car ``x0`` m ahead (centres) at ``v_cut`` m/s
    changes into the ego's lane between t = 2 s and t = 6 s (smoothstep lateral motion,
    heading from it). Defaults: the bumper gap shrinks to 11.5 m at t = 6 s and 7.5 m at
    t = 10 s (no contact); with x0 = 12 it reaches 0 at t = 7.5 s (rear-end contact)."""
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 10)
    ego = Track("ego", 4.5, 1.8, x=25.0 * t, y=np.zeros_like(t), psi=np.zeros_like(t),
                v=np.full_like(t, 25.0))
    s = np.clip((t - 2.0) / 4.0, 0.0, 1.0)
    y = 3.5 - 3.5 * s * s * (3.0 - 2.0 * s)
    vy = np.where((t > 2.0) & (t < 6.0), -3.5 * 6.0 * s * (1.0 - s) / 4.0, 0.0)
    cut = Track("cut_in", 4.5, 1.8, x=x0 + v_cut * t, y=y, psi=np.arctan2(vy, v_cut),
                v=np.hypot(v_cut, vy))
    return ConcreteScenario(t=t, ego=ego, objects=(cut,))


def main() -> None:
    settings = RiskSettings()
    surf = constant_surfaces()
    ego = EgoFuture.constant_velocity(0.0, 0.0, 0.0, 14.0, settings=settings)
    to = ObjectState("to", 0.0, 3.5, 0.0, 14.0, a0=1.0, omega0=-0.1)
    res = evaluate_scene(ego, [to], settings, surf)
    obj = res.objects[0]
    print("riskcore benchmark (Table II: horizon 3 s, dt 0.1 s, N_smp = 100); one core, "
          "medians of process CPU time; on a shared machine figures are noisy")
    print(f"load average now: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"scene: parallel cut-in of Fig. 3-5; {obj.n_collisions}/100 predicted "
          f"trajectories collide, WTTC {obj.wttc:.1f} s, min TTR {obj.min_ttr:.1f} s, "
          f"r = {res.r_dep:.4f}")

    fast = median_time(lambda: evaluate_scene(ego, [to], settings, surf), repeat=15,
                       number=40)
    ego_arr = np.column_stack([ego.x, ego.y, ego.psi, ego.v])
    ref_obj = RefObject(x=0.0, y=3.5, psi=0.0, v=14.0, length=4.5, width=1.8, mean_a=MEAN_A,
                        std_a=STD_A, mean_w=MEAN_W, std_w=STD_W)
    ref_s = RefSettings()
    ref_res = ref_object(ego_arr, (4.5, 1.8), ref_obj, ref_s)
    same = bool(np.array_equal(ref_res["ttr"], obj.ttr)
                and np.array_equal(ref_res["mask"], obj.evasion))
    ref = median_time(lambda: ref_object(ego_arr, (4.5, 1.8), ref_obj, ref_s), repeat=3)
    print(f"fast engine      : {fast * 1e3:8.3f} ms per object-scene (target <= 0.5)")
    print(f"reference (tests): {ref * 1e3:8.1f} ms per object-scene (plain numpy/python, "
          f"stepwise scan over every reaction step; same TTRs: {same})")
    print(f"ratio            : {ref / fast:8.0f} x")

    for label, sc in (("safe cut-in", cut_in_scenario()),
                      ("cut-in ending in contact", cut_in_scenario(x0=12.0))):
        r = evaluate_scenario(sc, settings)
        per_scenario = median_time(partial(evaluate_scenario, sc, settings), repeat=7)
        print(f"scenario 10 s at 10 Hz ({sc.t.size} scenes), {label}, packaged surfaces: "
              f"{per_scenario * 1e3:.1f} ms (target <= 50); risk {r.risk:.3f}, "
              f"min TTR {r.min_ttr:.1f} s")
    print("cost against the number of objects (one scene, objects on collision courses):")
    base = None
    for n_obj in (1, 2, 4):
        objs = [ObjectState(f"o{k}", 2.0 * k, 3.5 if k % 2 == 0 else -3.5, 0.0, 14.0, a0=1.0,
                            omega0=-0.1 if k % 2 == 0 else 0.1) for k in range(n_obj)]
        sec = median_time(partial(evaluate_scene, ego, objs, settings, surf),
                          repeat=15, number=20)
        base = base or sec
        print(f"  {n_obj} object(s): {sec * 1e3:7.3f} ms per scene, "
              f"{sec / n_obj * 1e3:7.3f} ms per object, {sec / base:5.2f} x the 1-object "
              f"cost")


if __name__ == "__main__":
    main()
