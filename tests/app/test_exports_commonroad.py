"""CommonRoad XML export, read back with commonroad-io: equal to the source within 1e-6.

Hand-made scenarios with hand-known goal regions and lanes, and scenarios from the builder.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from commonroad.common.file_reader import CommonRoadFileReader

from app.exports import ExportError, build_manifest, export_catalogue
from riskcore.scenario import ConcreteScenario, Track
from sampler.scenario.builder import build_scenario

TOL = 1e-6
PARAMS = [
    {"p_y1": -0.05, "p_t": 2.0, "p_a1": 0.5, "p_a2": 0.25, "p_a3": 1.0, "p_v0": 25.0,
     "dv": 4.0, "gap": 2.0},
    {"p_y1": 0.05, "p_t": 1.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0, "p_v0": 31.0,
     "dv": -1.0, "gap": 20.0},
]


def _track(track_id: str, x: list[float], y: list[float], psi: list[float],
           v: list[float], length: float = 4.0, width: float = 1.8) -> Track:
    return Track(track_id, length, width, x=np.array(x), y=np.array(y), psi=np.array(psi),
                 v=np.array(v))


def crossing() -> ConcreteScenario:
    """A cutter from the left whose centre reaches the marking (y = 1.875) a quarter of
    the way from step 2 (y = 2.0, x = 24) to step 3 (y = 1.5, x = 26): at x = 24.5."""
    return ConcreteScenario(
        t=np.array([0.0, 0.1, 0.2, 0.3, 0.4]),
        ego=_track("ego", [0.0, 3.0, 6.0, 9.0, 12.0], [0.0] * 5, [0.0] * 5, [30.0] * 5,
                   length=4.5),
        objects=(_track("cutter", [20.0, 22.0, 24.0, 26.0, 28.0], [3.0, 2.5, 2.0, 1.5, 1.0],
                        [-0.24, -0.24, -0.24, -0.24, -0.24], [20.5, 20.5, 20.5, 20.5, 20.5]),),
        params={"lane_width": 3.75},
    )


def _export(tmp_path: Path, scenarios: list[ConcreteScenario]) -> Path:
    manifest = build_manifest(seed=1, model_hash=None, sampler_settings={}, constraints=[],
                              p_region=None)
    out = tmp_path / "catalogue.zip"
    return export_catalogue("commonroad", [(s, {}) for s in scenarios], manifest, out)


def _read(path: Path, name: str, tmp_path: Path):  # type: ignore[no-untyped-def]
    with zipfile.ZipFile(path) as zf:
        target = tmp_path / name
        target.write_bytes(zf.read(name))
    return CommonRoadFileReader(str(target)).open()


def _assert_round_trip(source: ConcreteScenario, scenario, problems) -> None:  # type: ignore[no-untyped-def]
    assert scenario.dt == pytest.approx(source.dt, abs=1e-12)
    [obstacle] = scenario.dynamic_obstacles
    cutter = source.objects[0]
    assert obstacle.obstacle_shape.length == pytest.approx(cutter.length, abs=TOL)
    assert obstacle.obstacle_shape.width == pytest.approx(cutter.width, abs=TOL)
    states = [obstacle.initial_state, *obstacle.prediction.trajectory.state_list]
    assert [s.time_step for s in states] == list(range(source.t.shape[0]))
    got = np.array([[*s.position, s.orientation, s.velocity] for s in states])
    want = np.c_[cutter.x, cutter.y, cutter.psi, cutter.v]
    assert np.max(np.abs(got - want)) <= TOL
    [problem] = problems.planning_problem_dict.values()
    ego = source.ego
    init = problem.initial_state
    assert init.time_step == 0
    assert [*init.position, init.orientation, init.velocity] == pytest.approx(
        [ego.x[0], ego.y[0], ego.psi[0], ego.v[0]], abs=TOL)


def test_hand_made_cut_in_reads_back_with_its_goal_past_the_conflict(tmp_path: Path) -> None:
    source = crossing()
    path = _export(tmp_path, [source])
    scenario, problems = _read(path, "scenario_0000000.xml", tmp_path)
    _assert_round_trip(source, scenario, problems)
    [problem] = problems.planning_problem_dict.values()
    [goal] = problem.goal.state_list
    # the ego lane from x = 24.5 for 50 m: centre (49.5, 0), 50 m x 3.75 m, heading 0
    rect = goal.position
    assert (rect.rect_center.x, rect.rect_center.y) == pytest.approx((49.5, 0.0), abs=1e-9)
    assert (rect.length, rect.width, rect.orientation) == pytest.approx((50.0, 3.75, 0.0))
    # steps 1 .. 4 + 10 s / 0.1 s
    assert (goal.time_step.start, goal.time_step.end) == (1, 104)
    # three lanes of 3.75 m: left (centre 3.75), ego (0), right (-3.75)
    centres = sorted(float(lanelet.center_vertices[0, 1])
                     for lanelet in scenario.lanelet_network.lanelets)
    assert centres == pytest.approx([-3.75, 0.0, 3.75])


def test_builder_scenarios_read_back_equal_within_1e_6(tmp_path: Path) -> None:
    sources = [build_scenario(p, seed=i) for i, p in enumerate(PARAMS)]
    path = _export(tmp_path, sources)
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    assert names == ["catalogue.csv", "manifest.json", "scenario_0000000.xml",
                     "scenario_0000001.xml"]
    for i, source in enumerate(sources):
        scenario, problems = _read(path, f"scenario_{i:07d}.xml", tmp_path)
        _assert_round_trip(source, scenario, problems)
        [obstacle] = scenario.dynamic_obstacles
        states = obstacle.prediction.trajectory.state_list
        assert np.max(np.abs(np.array([s.acceleration for s in states])
                             - source.objects[0].a[1:])) <= TOL


def test_a_non_uniform_grid_is_named(tmp_path: Path) -> None:
    sc = crossing()
    bad = ConcreteScenario(t=np.array([0.0, 0.1, 0.2, 0.35, 0.4]), ego=sc.ego,
                           objects=sc.objects)
    with pytest.raises(ExportError, match=re.escape("item 0: CommonRoad needs a uniform "
                                                    "time grid")):
        _export(tmp_path, [bad])
    assert list(tmp_path.iterdir()) == []


_SAME_BYTES = """
import sys
from pathlib import Path
import zipfile
from tests.app.test_exports_commonroad import crossing, _export
with zipfile.ZipFile(_export(Path(sys.argv[1]), [crossing()])) as zf:
    print(zf.read("scenario_0000000.xml").hex())
"""


@pytest.mark.slow
def test_the_same_bytes_under_any_hash_seed(tmp_path: Path) -> None:
    """The scenario tags were written in a set's order, which follows the string hash seed:
    two processes wrote different bytes for the same scenario (found by the refactoring's
    behaviour snapshot). Exported under three hash seeds, the XML must be identical."""
    import os
    import subprocess
    import sys

    blobs = []
    for seed in ("1", "2", "3"):
        out = tmp_path / seed
        out.mkdir()
        env = dict(os.environ, PYTHONHASHSEED=seed)
        r = subprocess.run([sys.executable, "-c", _SAME_BYTES, str(out)], env=env,
                           capture_output=True, text=True, check=True,
                           cwd=Path(__file__).resolve().parents[2])
        blobs.append(r.stdout)
    assert blobs[0] == blobs[1] == blobs[2]
    with zipfile.ZipFile(tmp_path / "1" / "catalogue.zip") as zf:
        xml = zf.read("scenario_0000000.xml").decode()
    tags = re.findall(r"<scenarioTags>(.*?)</scenarioTags>", xml, re.S)[0]
    assert re.findall(r"<(\w+)/>", tags) == ["cut_in", "highway", "multi_lane"]
