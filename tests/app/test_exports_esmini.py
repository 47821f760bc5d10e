"""The OpenSCENARIO export replayed by esmini: geometry, collisions, modes, the logical scenario.

esmini is ``$SCENGEN_ESMINI`` or ``../shared/tools/esmini/bin/esmini`` next to the checkout;
without it these tests skip (a user's machine). esmini runs with its default settings
(trajectory filter 0.1 m, corner interpolation) and a fixed step of half scengen's, so
the export has to be right without special options. What is compared:

* box centre = esmini's reference point + R(h) * (bb_x, bb_y) against scengen's centre, and
  the heading, at every scengen time step esmini logs (<= 1 cm, <= 1e-3 rad);
* the first logged collision against the first step where scengen's boxes overlap
  (``riskcore.geometry.boxes_overlap``): within one scengen step, and the run stops there;
* ``test`` mode (constant-speed ego) against ``replay``: the same states;
* the logical scenario run with ``--param_dist`` / ``--param_permutation i``: one log per
  tuple, each identical to the per-scenario ``test`` file's.
"""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from app.exports import build_manifest, export_catalogue
from riskcore.geometry import boxes_overlap
from riskcore.scenario import ConcreteScenario, Track
from tests.app.esmini_run import (
    CUTIN_PARAMS,
    DEFAULT_ESMINI,
    ENV_VAR,
    ESMINI_SUTS,
    EntityLog,
    cutins,
    esmini_binary,
    run_esmini,
    with_controller,
)

pytestmark = pytest.mark.esmini

#: a slow cutter (0.9-1.2 m/s): 0.1 s steps are closer than esmini's 0.1 m filter
SLOW = {"p_y1": 0.5, "p_t": 3.0, "p_a1": -0.1, "p_a2": 0.0, "p_a3": 3.0, "p_v0": 1.2,
        "dv": 0.5, "gap": 1.0}
DT = 0.1
STEP = DT / 2
BOX_TOL = 0.01  # m
HEADING_TOL = 1e-3  # rad
CSV_TOL = 2e-6  # esmini's CSV has 6 decimals


@pytest.fixture(scope="module")
def esmini() -> Path:
    binary = esmini_binary()
    if binary is None:
        pytest.skip(f"esmini not found: set {ENV_VAR} to its binary or build it into "
                    f"{DEFAULT_ESMINI} (see shared/tools/esmini/README.md)")
    return binary


def _unzipped(tmp: Path, scenarios: list[ConcreteScenario], mode: str) -> Path:
    manifest = build_manifest(seed=1, model_hash=None, sampler_settings={}, constraints=[],
                              p_region=None)
    items = [(s, {"exposure_weight": 1.0 + i}) for i, s in enumerate(scenarios)]
    path = export_catalogue("xosc", items, manifest, tmp / f"{mode}.zip", mode=mode)
    out = tmp / mode
    with zipfile.ZipFile(path) as zf:
        zf.extractall(out)
    return out


@pytest.fixture(scope="module")
def runs(esmini: Path, tmp_path_factory: pytest.TempPathFactory
         ) -> dict[tuple[str, int], dict[str, EntityLog]]:
    tmp = tmp_path_factory.mktemp("esmini")
    scenarios = cutins(CUTIN_PARAMS)
    out: dict[tuple[str, int], dict[str, EntityLog]] = {}
    for mode in ("replay", "test"):
        folder = _unzipped(tmp, scenarios, mode)
        for i in range(len(scenarios)):
            name = f"scenario_{i:07d}"
            out[(mode, i)] = run_esmini(esmini, folder / f"{name}.xosc",
                                        folder / f"{name}.csv", step=STEP)
        if mode == "test":
            for i in range(len(scenarios)):
                out[("dist", i)] = run_esmini(
                    esmini, folder / "cutin_logical.xosc", folder / f"dist{i}.csv", step=STEP,
                    extra=("--param_dist", "cutin_distribution.xosc",
                           "--param_permutation", str(i)))
    return out


def _steps(log: EntityLog, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(scengen step indices, log row indices) of the scengen times esmini logged."""
    lt = np.asarray(log.t)
    rows = np.searchsorted(lt, t - 1e-9)
    ok = (rows < lt.shape[0]) & (np.abs(lt[np.minimum(rows, lt.shape[0] - 1)] - t) < 1e-6)
    return np.flatnonzero(ok), rows[ok]


def _errors(track: Track, t: np.ndarray, log: EntityLog) -> tuple[float, float, int]:
    steps, rows = _steps(log, t)
    cx, cy = log.centres()
    box = np.hypot(cx[rows] - track.x[steps], cy[rows] - track.y[steps])
    dh = np.angle(np.exp(1j * (np.asarray(log.h)[rows] - track.psi[steps])))
    return float(box.max()), float(np.abs(dh).max()), int(steps.shape[0])


def _scengen_collision(s: ConcreteScenario) -> float | None:
    n = s.t.shape[0]
    ego = np.c_[s.ego.x, s.ego.y, s.ego.psi, np.full(n, s.ego.length), np.full(n, s.ego.width)]
    c = s.objects[0]
    cut = np.c_[c.x, c.y, c.psi, np.full(n, c.length), np.full(n, c.width)]
    hit = np.flatnonzero(boxes_overlap(ego, cut))
    return float(s.t[hit[0]] - s.t[0]) if hit.size else None


def _esmini_collision(log: EntityLog) -> float | None:
    return next((t for t, ids in zip(log.t, log.collisions, strict=True) if ids), None)


@pytest.mark.parametrize("mode", ["replay", "test"])
def test_boxes_and_headings_match_scengen_at_every_step(
        runs: dict[tuple[str, int], dict[str, EntityLog]], mode: str) -> None:
    worst_box = worst_heading = 0.0
    for i, s in enumerate(cutins(CUTIN_PARAMS)):
        t = s.t - s.t[0]
        logs = runs[(mode, i)]
        for track in (s.ego, *s.objects):
            box, heading, n = _errors(track, t, logs[track.id])
            # logged up to the collision (where the run stops) or the end
            end = _scengen_collision(s)
            expected = t.shape[0] if end is None else round(end / DT) + 1
            assert n >= expected - 1, (mode, i, track.id, n)
            worst_box, worst_heading = max(worst_box, box), max(worst_heading, heading)
    assert worst_box <= BOX_TOL
    assert worst_heading <= HEADING_TOL


@pytest.mark.parametrize("mode", ["replay", "test"])
def test_collision_onset_within_one_step_and_the_run_stops_there(
        runs: dict[tuple[str, int], dict[str, EntityLog]], mode: str) -> None:
    seen = 0
    for i, s in enumerate(cutins(CUTIN_PARAMS)):
        ours = _scengen_collision(s)
        log = runs[(mode, i)]["ego"]
        theirs = _esmini_collision(log)
        if ours is None:
            assert theirs is None, (mode, i)
            assert log.t[-1] == pytest.approx(float(s.t[-1] - s.t[0]), abs=STEP + 1e-9)
            continue
        seen += 1
        assert theirs is not None, (mode, i)
        assert abs(theirs - ours) <= DT + 1e-9, (mode, i, theirs, ours)
        assert log.t[-1] <= theirs + STEP + 1e-9  # stopped on the collision
    assert seen >= 2  # the catalogue does hold collisions


def test_test_mode_with_a_constant_speed_ego_is_the_replay(
        runs: dict[tuple[str, int], dict[str, EntityLog]]) -> None:
    for i in range(len(CUTIN_PARAMS)):
        replay, test = runs[("replay", i)], runs[("test", i)]
        for name in ("ego", "cutter"):
            assert replay[name].t == test[name].t
            for a, b in zip(replay[name].centres(), test[name].centres(), strict=True):
                assert np.max(np.abs(a - b)) <= CSV_TOL, (i, name)
            assert np.max(np.abs(np.subtract(replay[name].h, test[name].h))) <= CSV_TOL


def test_parameter_distribution_gives_one_run_per_tuple_equal_to_its_scenario(
        esmini: Path, runs: dict[tuple[str, int], dict[str, EntityLog]],
        tmp_path: Path) -> None:
    folder = _unzipped(tmp_path, cutins(CUTIN_PARAMS), "test")
    proc = subprocess.run([str(esmini), "--headless", "--osc", "cutin_logical.xosc",
                           "--param_dist", "cutin_distribution.xosc",
                           "--return_nr_permutations", "--disable_stdout",
                           "--logfile_path", str(tmp_path / "n.log")],
                          cwd=folder, capture_output=True, timeout=60, check=False)
    assert proc.returncode == len(CUTIN_PARAMS)
    for i in range(len(CUTIN_PARAMS)):
        single, dist = runs[("test", i)], runs[("dist", i)]
        for name in ("ego", "cutter"):
            assert single[name].t == dist[name].t
            for a, b in zip(single[name].centres(), dist[name].centres(), strict=True):
                assert np.max(np.abs(a - b)) <= CSV_TOL, (i, name)


def test_a_slow_cutter_keeps_every_vertex_esmini_would_otherwise_merge(
        esmini: Path, tmp_path: Path) -> None:
    [s] = cutins([SLOW])
    cutter = s.objects[0]
    assert np.min(np.hypot(np.diff(cutter.x), np.diff(cutter.y))) < 0.1  # would merge
    t = s.t - s.t[0]
    for mode in ("replay", "test"):
        folder = _unzipped(tmp_path, [s], mode)
        logs = run_esmini(esmini, folder / "scenario_0000000.xosc", folder / "s.csv", step=STEP)
        box, heading, _ = _errors(cutter, t, logs["cutter"])
        # vertices are thinned to >= 0.12 m, so esmini interpolates over 0.2 s where the
        # cutter is below 1.2 m/s: the box stays within 1 cm, the heading within 3e-3 rad
        assert box <= BOX_TOL, mode
        assert heading <= 3e-3, mode


# ------------------------------------------------- esmini's own controllers on the ego

#: a cut-in where esmini's R157 FSM model brakes, falls back and re-accelerates: it is
#: still closing on the cutter when the scenario's duration (9.0 s) is over
LATE = {"p_y1": 0.0899, "p_t": 1.644, "p_a1": -0.5114, "p_a2": -0.2856, "p_a3": 0.1218,
        "p_v0": 33.0558, "dv": 3.0909, "gap": 6.473}
#: the export's vehicle performance (app.exports._osc.MAX_SPEED) and run time limit
MAX_SPEED = 70.0
STOP_SLACK = 30.0
FOLLOW_HORIZON = 60.0


def _schema() -> etree.XMLSchema:
    files = importlib.metadata.files("scenariogeneration") or []
    [path] = [f for f in files if f.name == "OpenSCENARIO_1_2.xsd"]
    return etree.XMLSchema(etree.parse(str(path.locate())))


@pytest.fixture(scope="module")
def sut_runs(esmini: Path, tmp_path_factory: pytest.TempPathFactory
             ) -> tuple[list[ConcreteScenario], dict[tuple[str, int], dict[str, EntityLog]],
                        tuple[float, float]]:
    """Every test-mode scenario driven by each of esmini's controllers (and none)."""
    tmp = tmp_path_factory.mktemp("esmini_suts")
    scenarios = cutins([*CUTIN_PARAMS, LATE])
    folder = _unzipped(tmp, scenarios, "test")
    road = json.loads((folder / "manifest.json").read_text())["export"]["road_x_range"]
    schema = _schema()
    out: dict[tuple[str, int], dict[str, EntityLog]] = {}
    for i in range(len(scenarios)):
        name = f"scenario_{i:07d}"
        source = (folder / f"{name}.xosc").read_bytes()
        out[("none", i)] = run_esmini(esmini, folder / f"{name}.xosc",
                                      folder / f"{name}_none.csv", step=STEP)
        for j, (label, (controller, props)) in enumerate(ESMINI_SUTS.items()):
            xosc = folder / f"{name}_{j}.xosc"
            data = with_controller(source, controller, props)
            assert schema.validate(etree.fromstring(data)), (label, schema.error_log)
            xosc.write_bytes(data)
            out[(label, i)] = run_esmini(esmini, xosc, xosc.with_suffix(".csv"), step=STEP)
    return scenarios, out, (float(road[0]), float(road[1]))


def _cutter_error(s: ConcreteScenario, log: EntityLog) -> float:
    """Largest distance (m) of the logged cutter box centre from the scenario's, at the
    logged scenario steps up to its duration and, after it, from its last velocity kept."""
    c = s.objects[0]
    t = s.t - s.t[0]
    lt = np.asarray(log.t)
    cx, cy = log.centres()
    steps, rows = _steps(log, t)
    err = np.hypot(cx[rows] - c.x[steps], cy[rows] - c.y[steps])
    after = lt > t[-1] + 1e-9
    span = lt[after] - t[-1]
    ex = c.x[-1] + c.v[-1] * np.cos(c.psi[-1]) * span
    ey = c.y[-1] + c.v[-1] * np.sin(c.psi[-1]) * span
    err_after = np.hypot(cx[after] - ex, cy[after] - ey)
    return float(max(err.max(), err_after.max(initial=0.0)))


def _conflict_over(s: ConcreteScenario, ego: EntityLog, cut: EntityLog, row: int) -> bool:
    """The export's conflict-over rule on logged states (both headings 0 after the
    scenario's duration): the ego not faster; contact beyond the follow horizon; the
    cutter beside the ego's path; or the ego ahead and not slower."""
    (ex, ey), (cx, cy) = (np.array([a[row] for a in e.centres()]) for e in (ego, cut))
    c = s.objects[0]
    dv = ego.speed[row] - cut.speed[row]
    gap = cx - ex - (s.ego.length + c.length) / 2
    behind = ex - cx - (s.ego.length + c.length) / 2
    return bool(dv <= 1e-6 or (gap > 0 and gap / dv > FOLLOW_HORIZON)
                or abs(cy - ey) > (s.ego.width + c.width) / 2
                or (behind > 0 and dv >= -1e-6))


def test_the_cut_in_happens_as_sampled_whatever_the_ego_does(
        sut_runs: tuple[list[ConcreteScenario], dict[tuple[str, int], dict[str, EntityLog]],
                        tuple[float, float]]) -> None:
    scenarios, runs, _ = sut_runs
    early = set()
    for (label, i), logs in runs.items():
        s = scenarios[i]
        assert _cutter_error(s, logs["cutter"]) <= BOX_TOL, (label, i)
        ego = logs["ego"]
        lead_in = float(s.provenance["lead_in"])  # the cutter starts moving sideways then
        if any(v < ego.speed[0] - 0.5 for t, v in zip(ego.t, ego.speed, strict=True)
               if t < lead_in):
            early.add(label)
    # some controllers brake before the cut-in starts (the old distance trigger then
    # started it late or never): RSS and FSM on the second cut-in
    assert {"R157 RSS", "R157 FSM"} <= early


def test_vehicles_stay_on_the_road_and_every_collision_is_real(
        sut_runs: tuple[list[ConcreteScenario], dict[tuple[str, int], dict[str, EntityLog]],
                        tuple[float, float]]) -> None:
    scenarios, runs, (x_start, x_end) = sut_runs
    braked = set()
    for (label, i), logs in runs.items():
        s = scenarios[i]
        for track, log in ((s.ego, logs["ego"]), (s.objects[0], logs["cutter"])):
            x = np.asarray(log.x)
            # never at either end of the road, where esmini holds a vehicle
            assert x_start + 1.0 < x.min() and x.max() < x_end - 1.0, (label, i, track.id)
            step = np.hypot(np.diff(log.x), np.diff(log.y)) / np.diff(log.t)
            assert step.max() <= MAX_SPEED, (label, i, track.id)  # no jumps
        ego, cut = logs["ego"], logs["cutter"]
        braked |= {label} if min(ego.speed) < ego.speed[0] - 0.5 else set()
        hits = [k for k, ids in enumerate(ego.collisions) if ids]
        for k in hits:
            c = s.objects[0]
            (ex, ey), (cx, cy) = ([a[k] for a in e.centres()] for e in (ego, cut))
            boxes = (np.array([[ex, ey, ego.h[k], s.ego.length + 2e-3, s.ego.width + 2e-3]]),
                     np.array([[cx, cy, cut.h[k], c.length + 2e-3, c.width + 2e-3]]))
            assert boxes_overlap(*boxes)[0], (label, i, ego.t[k])
            assert abs(ego.speed[k] - cut.speed[k]) <= MAX_SPEED
    assert braked == set(ESMINI_SUTS)  # every controller did brake


def test_a_run_ends_at_a_collision_a_resolved_conflict_or_the_time_limit(
        sut_runs: tuple[list[ConcreteScenario], dict[tuple[str, int], dict[str, EntityLog]],
                        tuple[float, float]]) -> None:
    scenarios, runs, _ = sut_runs
    for (label, i), logs in runs.items():
        s = scenarios[i]
        ego, cut = logs["ego"], logs["cutter"]
        duration = float(s.t[-1] - s.t[0])
        end = ego.t[-1]
        if any(ego.collisions):
            assert ego.collisions[-1], (label, i)  # stopped on the collision
            continue
        assert end >= duration - 1e-9, (label, i)
        if end < duration + STOP_SLACK - STEP:
            assert _conflict_over(s, ego, cut, -1), (label, i, end)
        if end > duration + STEP:  # ran on: the conflict was not over a step earlier
            assert not _conflict_over(s, ego, cut, -2), (label, i, end)
    # the late cut-in: the braking FSM model still closes in when the cutter's scripted
    # motion ends; the run goes on until contact lies beyond the follow horizon
    late = len(CUTIN_PARAMS)
    assert runs[("R157 FSM", late)]["ego"].t[-1] > float(scenarios[late].t[-1]) + 1.0
