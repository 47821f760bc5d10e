"""Host esmini's own controllers on the ego of the test-mode OpenSCENARIO export.

N random cut-ins (drawn as in benchmarks/bench_exports.py, seeded) are exported in
``test`` mode; every scenario is run by esmini (``$SCENGEN_ESMINI`` or
../shared/tools/esmini/bin/esmini, 0.05 s steps, collision detection) with the ego
keeping its speed (no controller) and driven by each of esmini's stand-in systems under
test (``ACCController``; ``ALKS_R157SM_Controller`` with the models ReferenceDriver,
Regulation, RSS, FSM). Prints per controller:

* runs, collisions, braking runs (the ego's speed fell by > 0.5 m/s);
* ``road end``: runs where a vehicle came within 1 m of either end of the road (esmini
  holds a vehicle there: an ego "stuck" at the end is an artefact of a short road);
* ``max speed``: the largest speed implied by consecutive logged positions (a vehicle
  clamped at the road's end and released, or teleported, shows as thousands of m/s);
* ``fake coll.``: collisions esmini reports where the logged boxes do not overlap
  (``riskcore.geometry.boxes_overlap`` on the logged boxes grown by 1 mm), and the largest
  relative speed at a reported collision;
* ``cut-in moved``: runs where the cutter's box centre differs by more than 1 cm from the
  scenario's (at every logged scenario step up to its duration, and from the constant
  velocity it keeps after that): the cut-in must not depend on what the ego does;
* how the runs ended: a collision, the conflict over at the scenario's duration or later,
  or the time limit.

    PYTHONPATH=. .venv/bin/python scripts/esmini_controller_check.py --n 200 --seed 11
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_exports import scenarios  # noqa: E402

from app.exports import build_manifest, export_catalogue  # noqa: E402
from riskcore.geometry import boxes_overlap  # noqa: E402
from riskcore.scenario import ConcreteScenario  # noqa: E402
from tests.app.esmini_run import (  # noqa: E402
    ESMINI_SUTS,
    EntityLog,
    esmini_binary,
    run_esmini,
    with_controller,
)

STEP = 0.05
GRID = 0.1
#: the time limit after the scenario's duration (app.exports._osc.STOP_SLACK)
STOP_SLACK = 30.0


@dataclass
class Tally:
    runs: int = 0
    collisions: int = 0
    braking: int = 0
    road_end: int = 0
    max_speed: float = 0.0
    fake: int = 0
    impact: float = 0.0
    moved: int = 0
    worst_cutter: float = 0.0
    ends: Counter[str] = field(default_factory=Counter)


def _boxes(log: EntityLog, length: float, width: float) -> np.ndarray:
    """The logged boxes (centre, heading, size) grown by 1 mm on each side."""
    cx, cy = log.centres()
    n = cx.shape[0]
    return np.c_[cx, cy, np.asarray(log.h), np.full(n, length + 0.002),
                 np.full(n, width + 0.002)]


def expected_cutter(s: ConcreteScenario, times: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                      np.ndarray]:
    """Which logged times to compare and the cutter's box centre then: the scenario's
    steps up to its duration, after it its last velocity kept."""
    c = s.objects[0]
    t = s.t - s.t[0]
    duration = float(t[-1])
    k = np.rint(times / GRID).astype(int)
    on_grid = (np.abs(times - k * GRID) < 1e-6) & (k < t.shape[0])
    after = times > duration + 1e-9
    use = on_grid | after
    kk = np.minimum(k, t.shape[0] - 1)
    span = np.where(after, times - duration, 0.0)
    x = np.where(after, c.x[-1] + c.v[-1] * np.cos(c.psi[-1]) * span, c.x[kk])
    y = np.where(after, c.y[-1] + c.v[-1] * np.sin(c.psi[-1]) * span, c.y[kk])
    return use, x, y


def check(s: ConcreteScenario, logs: dict[str, EntityLog], road: tuple[float, float],
          tally: Tally) -> None:
    ego, cut = logs["ego"], logs["cutter"]
    tally.runs += 1
    t = np.asarray(ego.t)
    hit = [i for i, ids in enumerate(ego.collisions) if ids]
    tally.collisions += bool(hit)
    tally.braking += min(ego.speed) < ego.speed[0] - 0.5
    for log in (ego, cut):
        x = np.asarray(log.x)
        if x.min() < road[0] + 1.0 or x.max() > road[1] - 1.0:
            tally.road_end += 1
            break
    for log in (ego, cut):
        lt = np.asarray(log.t)
        if lt.shape[0] > 1:
            v = np.hypot(np.diff(log.x), np.diff(log.y)) / np.diff(lt)
            tally.max_speed = max(tally.max_speed, float(v.max()))
    if hit:
        i = hit[0]
        c = s.objects[0]
        overlap = boxes_overlap(_boxes(ego, s.ego.length, s.ego.width)[i:i + 1],
                                _boxes(cut, c.length, c.width)[i:i + 1])
        tally.fake += not bool(overlap[0])
        tally.impact = max(tally.impact, abs(ego.speed[i] - cut.speed[i]))
    use, ex, ey = expected_cutter(s, np.asarray(cut.t))
    cx, cy = cut.centres()
    err = float(np.max(np.hypot(cx[use] - ex[use], cy[use] - ey[use])))
    tally.worst_cutter = max(tally.worst_cutter, err)
    tally.moved += err > 0.01
    duration = float(s.t[-1] - s.t[0])
    if hit:
        tally.ends["collision"] += 1
    elif t[-1] >= duration + STOP_SLACK - STEP:
        tally.ends["time limit"] += 1
    elif t[-1] <= duration + STEP + 1e-9:
        tally.ends["over at duration"] += 1
    else:
        tally.ends["over later"] += 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    binary = esmini_binary()
    if binary is None:
        print("esmini not found: set SCENGEN_ESMINI", file=sys.stderr)
        return 2
    sc = scenarios(args.n, args.seed)
    manifest = build_manifest(seed=args.seed, model_hash=None, sampler_settings={},
                              constraints=[], p_region=None)
    suts: dict[str, tuple[str, dict[str, str]] | None] = {"none (keeps speed)": None,
                                                          **ESMINI_SUTS}
    tallies = {name: Tally() for name in suts}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        path = export_catalogue("xosc", [(s, {}) for s in sc], manifest, tmp / "test.zip",
                                mode="test")
        folder = tmp / "test"
        with zipfile.ZipFile(path) as zf:
            zf.extractall(folder)
        road = tuple(json.loads((folder / "manifest.json").read_text())
                     ["export"]["road_x_range"])
        print(f"{args.n} cut-ins (seed {args.seed}), road x {road[0]:.0f} .. {road[1]:.0f} m")
        for i, s in enumerate(sc):
            name = f"scenario_{i:07d}.xosc"
            source = (folder / name).read_bytes()
            for j, (label, sut) in enumerate(suts.items()):
                xosc = folder / name if sut is None else folder / f"s{i}_{j}.xosc"
                if sut is not None:
                    xosc.write_bytes(with_controller(source, sut[0], sut[1]))
                logs = run_esmini(binary, xosc, folder / f"s{i}_{j}.csv", step=STEP)
                check(s, logs, (float(road[0]), float(road[1])), tallies[label])
    print(f"{'controller':<22}{'runs':>5}{'coll.':>6}{'brake':>6}{'road end':>9}"
          f"{'max speed':>10}{'fake coll.':>11}{'max impact':>11}{'cut-in moved':>13}"
          f"{'max cutter err':>15}  ends")
    for label, t in tallies.items():
        ends = ", ".join(f"{k} {v}" for k, v in sorted(t.ends.items()))
        print(f"{label:<22}{t.runs:>5}{t.collisions:>6}{t.braking:>6}{t.road_end:>9}"
              f"{t.max_speed:>10.1f}{t.fake:>11}{t.impact:>11.2f}{t.moved:>13}"
              f"{t.worst_cutter:>15.2e}  {ends}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
