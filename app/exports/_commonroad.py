"""CommonRoad XML export: one zip with every scenario as a CommonRoad 2020a XML file.

Zip layout (entries sorted by name, fixed timestamps)::

    catalogue.csv            the CSV export's rows with a leading ``file`` column
    manifest.json            the manifest plus an ``export`` section
    scenario_0000000.xml     one CommonRoad scenario + planning problem per scenario
    ...

Each file is written by ``commonroad-io`` (``CommonRoadFileWriter``, XML, 12 decimals,
validated against its XSD):

* the time step is the scenario's (the grid must be uniform); CommonRoad time step i is
  scenario time t_0 + i dt;
* the road: one lanelet per lane, straight along +x, ``lane_width`` wide, the ego lane
  centred on y = 0, as many lanes as the vehicles' centres need (at least one each side,
  as in the OpenSCENARIO export), spanning every vehicle's x range +- 50 m;
  lanelet type highway, dashed markings between lanes, solid at the road edges;
* every object besides the ego (the cutter) is a ``DynamicObstacle`` of type car, a
  rectangle of its length and width centred on its position (CommonRoad positions are
  shape centres, as scengen's), with its states at every step (position, orientation,
  velocity, acceleration and yaw rate when known);
* the ego is the ``PlanningProblem``: its initial state at step 0 (position, orientation,
  velocity, acceleration 0, yaw rate 0, slip angle 0) and a goal region past the conflict:
  the ego lane from the point where the cutter's centre crosses onto the ego lane's
  marking (``crossing_x``) for ``GOAL_LENGTH`` m, reachable from step 1 to the scenario's
  last step + ``GOAL_SLACK`` s.
"""

from __future__ import annotations

import datetime as dt
import tempfile
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from app.exports._common import ExportError, Row, dumps
from app.exports._xosc import (
    INDEX_DIGITS,
    INDEX_FILE,
    MANIFEST_FILE,
    RoadExtent,
    _creation_date,
    _lane_width,
    assemble_zip,
    write_scratch,
)
from riskcore import ConcreteScenario, Track

Item = tuple[int, ConcreteScenario, Mapping[str, Any], Row]

#: decimals written for every number (read back within 1e-10 m)
DECIMALS = 12
#: length of the goal region along the ego lane (m) and time slack after the scenario (s)
GOAL_LENGTH = 50.0
GOAL_SLACK = 10.0
#: id of the first obstacle; the planning problem gets the next free id
FIRST_ID = 100


def scenario_file_name(index: int) -> str:
    return f"scenario_{index:0{INDEX_DIGITS}d}.xml"


def _uniform_dt(scenario: ConcreteScenario, index: int) -> float:
    steps = np.diff(scenario.t)
    step = float(np.median(steps))
    if not np.all(np.abs(steps - step) <= 1e-9 * max(step, 1.0)):
        raise ExportError(f"item {index}: CommonRoad needs a uniform time grid; the steps "
                          f"range from {steps.min()} to {steps.max()} s")
    return step


def crossing_x(scenario: ConcreteScenario, lane_width: float) -> float:
    """x (m) of the first object's centre when it first reaches the ego lane's marking
    (|y| <= lane_width / 2, linearly interpolated between steps); the ego's last x when
    it never does."""
    obj = scenario.objects[0]
    inside = np.abs(obj.y) <= lane_width / 2
    if not inside.any():
        return float(scenario.ego.x[-1])
    k = int(np.argmax(inside))
    if k == 0:
        return float(obj.x[0])
    y0, y1 = abs(float(obj.y[k - 1])), abs(float(obj.y[k]))
    f = (y0 - lane_width / 2) / (y0 - y1)
    return float(obj.x[k - 1] + f * (obj.x[k] - obj.x[k - 1]))


def scenario_xml(scenario: ConcreteScenario, *, index: int, lane_width: float,
                 date: dt.datetime, scratch_dir: Path) -> bytes:
    """One scenario as CommonRoad XML bytes (see the module doc)."""
    from commonroad.common.common_lanelet import LaneletType, LineMarking
    from commonroad.common.common_scenario import ScenarioID
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import FileFormat, Interval
    from commonroad.geometry.obstacle_shapes.rect_obstacle_shape import RectObstacleShape
    from commonroad.geometry.occupancy.rect_occupancy import RectOccupancy
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.lanelet import Lanelet, LaneletNetwork
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.scenario import Scenario, Tag
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory
    from shapely import Point

    if not scenario.objects:
        raise ExportError(f"item {index}: the scenario has no objects besides the ego")
    step = _uniform_dt(scenario, index)
    extent = RoadExtent(lane_width=lane_width)
    extent.add(scenario)
    n_left, n_right = extent.lanes()
    x_start, x_end = extent.x_range()
    xs = np.array([x_start, x_end])
    out = Scenario(dt=step, scenario_id=ScenarioID(country_id="ZAM", map_name="scengen",
                                                   map_id=index + 1),
                   tags={Tag.HIGHWAY, Tag.MULTI_LANE, Tag.CUT_IN})
    lanelets = []
    lanes = list(range(n_left, -n_right - 1, -1))  # lane offsets from the ego lane, left first
    for j, lane in enumerate(lanes):
        yc = lane * lane_width
        left, right = yc + lane_width / 2, yc - lane_width / 2
        lanelets.append(Lanelet(
            np.c_[xs, [left, left]], np.c_[xs, [yc, yc]], np.c_[xs, [right, right]], j + 1,
            adjacent_left=j if j > 0 else None,
            adjacent_left_same_direction=True if j > 0 else None,
            adjacent_right=j + 2 if j + 1 < len(lanes) else None,
            adjacent_right_same_direction=True if j + 1 < len(lanes) else None,
            line_marking_left_vertices=LineMarking.SOLID if j == 0 else LineMarking.DASHED,
            line_marking_right_vertices=(LineMarking.SOLID if j + 1 == len(lanes)
                                         else LineMarking.DASHED),
            lanelet_type={LaneletType.HIGHWAY},
        ))
    out.add_objects(LaneletNetwork.create_from_lanelet_list(lanelets))

    def state_values(track: Track, i: int) -> dict[str, Any]:
        values: dict[str, Any] = {
            "position": np.array([float(track.x[i]), float(track.y[i])]),
            "orientation": float(track.psi[i]), "velocity": float(track.v[i]),
        }
        if track.a is not None:
            values["acceleration"] = float(track.a[i])
        if track.yaw_rate is not None:
            values["yaw_rate"] = float(track.yaw_rate[i])
        return values

    n = scenario.t.shape[0]
    for k, obj in enumerate(scenario.objects):
        shape = RectObstacleShape(width=float(obj.width), length=float(obj.length))
        first = state_values(obj, 0)
        first.setdefault("acceleration", 0.0)
        first.setdefault("yaw_rate", 0.0)
        initial = InitialState(time_step=0, slip_angle=0.0, **first)
        states = [CustomState(time_step=i, **state_values(obj, i)) for i in range(1, n)]
        prediction = TrajectoryPrediction(Trajectory(1, states), shape) if states else None
        out.add_objects(DynamicObstacle(FIRST_ID + k, ObstacleType.CAR, shape, initial,
                                        prediction))
    ego = scenario.ego
    ego_initial = InitialState(
        time_step=0, position=np.array([float(ego.x[0]), float(ego.y[0])]),
        orientation=float(ego.psi[0]), velocity=float(ego.v[0]), acceleration=0.0,
        yaw_rate=0.0, slip_angle=0.0)
    x_goal = crossing_x(scenario, lane_width)
    last = n - 1 + round(GOAL_SLACK / step)
    goal = GoalRegion([CustomState(
        time_step=Interval(1, last),
        position=RectOccupancy(Point(x_goal + GOAL_LENGTH / 2, 0.0), lane_width,
                               GOAL_LENGTH, 0.0))])
    problem = PlanningProblem(FIRST_ID + len(scenario.objects), ego_initial, goal)
    writer = CommonRoadFileWriter(out, PlanningProblemSet([problem]), author="scengen",
                                  affiliation="scengen", source="scengen cut-in catalogue",
                                  tags={Tag.HIGHWAY, Tag.MULTI_LANE, Tag.CUT_IN},
                                  decimal_precision=DECIMALS, file_format=FileFormat.XML)
    # a name that does not exist yet (commonroad-io prints a line when it replaces a file)
    name = str(scratch_dir / f"{index}.xml")
    try:
        with warnings.catch_warnings():
            # commonroad-io warns about the placeholder location (no geo reference)
            warnings.simplefilter("ignore", UserWarning)
            writer.write_to_file(name, OverwriteExistingFile.ALWAYS, check_validity=True)
        root = etree.parse(name).getroot()
    except Exception as exc:  # commonroad-io raises assorted types on invalid input
        raise ExportError(f"item {index}: commonroad-io could not write the scenario: "
                          f"{exc}") from None
    finally:
        Path(name).unlink(missing_ok=True)
    root.set("date", date.strftime("%Y-%m-%d"))  # commonroad-io writes today's date
    # commonroad-io writes the tags in the order of a set of enums, which follows the
    # process's string hash seed: sort them so that every process writes the same bytes
    for tags in root.iter("scenarioTags"):
        tails = [e.tail for e in tags]  # the indentation stays where it was
        tags[:] = sorted(tags, key=lambda e: str(e.tag))
        for e, tail in zip(tags, tails, strict=True):
            e.tail = tail
    data: bytes = etree.tostring(root, pretty_print=True, xml_declaration=True,
                                 encoding="UTF-8")
    return data


def write_commonroad_zip(items: Iterator[Item], manifest: Mapping[str, Any],
                         path: Path) -> None:
    """Stream the scenarios into a scratch zip, then assemble the final sorted zip."""
    if "export" in manifest:
        raise ExportError("manifest: the key 'export' is reserved for the commonroad export")
    try:
        import commonroad  # noqa: F401
    except ImportError:
        raise ExportError("the commonroad export needs the commonroad-io package "
                          "(pip install commonroad-io)") from None
    date = _creation_date(manifest)
    scratch_zip = path.with_name(path.name + ".scenarios")
    scratch_csv = path.with_name(path.name + ".csv")
    scratch_dir = Path(tempfile.mkdtemp(prefix=".commonroad-", dir=path.parent))

    def content(index: int, scenario: ConcreteScenario, row: Row, name: str) -> bytes:
        return scenario_xml(scenario, index=index, lane_width=_lane_width(scenario, index),
                            date=date, scratch_dir=scratch_dir)

    try:
        count = write_scratch(items, scratch_zip, scratch_csv, "commonroad",
                              scenario_file_name, content)
        full_manifest = dict(manifest)
        full_manifest["export"] = {
            "format": "commonroad",
            "n_scenarios": count,
            "commonroad": "2020a XML (commonroad-io)",
            "index_file": INDEX_FILE,
            "scenario_files": f"scenario_<index, {INDEX_DIGITS} digits>.xml",
            "ego": "planning problem: initial state at time step 0; goal region: the ego "
                   f"lane for {GOAL_LENGTH:g} m from where the cutter's centre reaches the "
                   f"ego lane's marking, time steps 1 .. last + {GOAL_SLACK:g} s",
            "objects": "dynamic obstacles (car, rectangle centred on the position), one "
                       "state per time step",
            "time": "CommonRoad time step i = scenario time t[0] + i * dt",
            "decimals": DECIMALS,
        }
        manifest_bytes = (dumps(full_manifest, indent=2) + "\n").encode("utf-8")
        assemble_zip(path, {INDEX_FILE: scratch_csv, MANIFEST_FILE: manifest_bytes},
                     scratch_zip)
    finally:
        for scratch in (scratch_zip, scratch_csv):
            if scratch.exists():
                scratch.unlink()
        for leftover in scratch_dir.iterdir():
            leftover.unlink()
        scratch_dir.rmdir()
