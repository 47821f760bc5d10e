"""OpenSCENARIO 1.2 export: one zip with every scenario as a ``.xosc``, one road, an index.

Zip layout (entries sorted by name, fixed timestamps, so the same catalogue gives the
same bytes)::

    catalogue.csv                 the CSV export's rows with a leading ``file`` column
    manifest.json                 the manifest plus an ``export`` section (see below)
    road.xodr                     OpenDRIVE 1.7: one straight one-way multi-lane road
    scenario_0000000.xosc         one OpenSCENARIO 1.2 file per scenario (catalogue index)
    ...

Coordinates: scengen's road frame (x along the road in the driving direction, y to the
left, heading psi counter-clockwise from +x, z up) *is* the OpenSCENARIO/OpenDRIVE world
frame (ISO 8855 right-handed, heading counter-clockwise from +x): x, y and psi are written
unchanged as ``WorldPosition(x, y, h=psi)``. The ego lane's centre line is y = 0.

Reference point: OpenSCENARIO positions refer to a vehicle's reference point and the
``BoundingBox`` centre is given relative to it. scengen positions are box centres, so each
vehicle's bounding box has its centre at the reference point (``Center x=0 y=0``,
z = half the height) and the trajectory vertices are the scengen centres as they are.
Simulators that put the reference point on the rear axle read the box centre from the
file, so they place the vehicle correctly.

Trajectories: every vehicle (ego included) gets a ``FollowTrajectoryAction`` whose
``Trajectory`` shape is a ``Polyline`` with one ``Vertex`` per time step (time
t_i - t_0, ``WorldPosition(x_i, y_i, h=psi_i)``), ``TimeReference/Timing`` absolute with
scale 1 and offset 0, following mode ``position``. Simulation time 0 is the scenario's
first time step; for the usual grid that starts at t_0 = 0 the vertex times are the
scenario's times exactly. A grid that starts elsewhere is shifted rather than expressed
with the ``Timing`` offset, because simulators disagree on that offset's sign (esmini
looks up trajectory time = simulation time * scale + offset); t_0 is kept in the file
header's ``scengen.t0`` property. ``Init`` teleports each vehicle to its first vertex with
its first speed; the storyboard stops at simulation time t_last - t_0.

Road: the reference line is the road's left edge; all lanes are right lanes (ids -1, -2,
...) driving in +x, ``lane_width`` wide (the scenario's ``params["lane_width"]``, else its
``provenance["lane_width"]``, else ``DEFAULT_LANE_WIDTH``; all scenarios of a catalogue
must agree). The ego lane has
id -(n_left + 1) and its centre at y = 0; there are at least one lane to its left and one
to its right, and as many more as the vehicles' centres need. The road spans every
vehicle's x range plus ``ROAD_MARGIN`` m on both sides.

Validation: each ``.xosc`` against ``OpenSCENARIO_1_2.xsd`` and the ``.xodr`` against
``opendrive_17_core.xsd`` (and its included siblings), both shipped with
``scenariogeneration``; any error fails the export with the first schema messages.
"""

from __future__ import annotations

import datetime as dt
import functools
import importlib.metadata
import math
import os
import threading
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree
from scenariogeneration import xodr, xosc

from app.exports._common import ExportError, Row, dumps
from app.exports._tabular import CsvRowWriter
from datasets.cutin_model import DEFAULT_LANE_WIDTH
from riskcore.scenario import ConcreteScenario, Track

Item = tuple[int, ConcreteScenario, Mapping[str, Any], Row]

OSC_XSD = "OpenSCENARIO_1_2.xsd"
ODR_XSD = "opendrive_17_core.xsd"
ROAD_FILE = "road.xodr"
MANIFEST_FILE = "manifest.json"
INDEX_FILE = "catalogue.csv"
#: digits of the catalogue index in scenario file names (zero-padded, so names sort)
INDEX_DIGITS = 7
#: metres of road before the first and after the last vehicle position
ROAD_MARGIN = 50.0
#: vehicle properties scengen does not model (m, rad, m/s, m/s^2)
VEHICLE_HEIGHT = 1.5
WHEEL_DIAMETER = 0.7
MAX_STEERING = 0.5
AXLE_FRACTION = 0.3  # axles at +-0.3 length from the box centre
MAX_SPEED = 70.0
MAX_ACCELERATION = 10.0
MAX_DECELERATION = 10.0
#: header date when the manifest carries no ``created_at`` (keeps exports deterministic)
DEFAULT_DATE = dt.datetime(1970, 1, 1)
#: zip entry timestamp (the earliest a zip can hold) and permissions
ZIP_DATE = (1980, 1, 1, 0, 0, 0)
ZIP_MODE = 0o644

# scenariogeneration keeps the OpenSCENARIO version in a class attribute shared by every
# object, and the lxml schema objects are shared too; building, serialising and validating
# happen under this lock so that concurrent exports in threads cannot interfere.
_LOCK = threading.Lock()


def schema_path(name: str) -> Path:
    """Where the installed ``scenariogeneration`` distribution keeps the XSD ``name``."""
    try:
        files = importlib.metadata.files("scenariogeneration") or []
    except importlib.metadata.PackageNotFoundError:
        raise ExportError("the scenariogeneration package is not installed") from None
    for file in files:
        if file.name == name:
            return Path(str(file.locate()))
    raise ExportError(f"{name} not found in the scenariogeneration installation")


@functools.cache
def _schema(name: str) -> etree.XMLSchema:
    path = schema_path(name)
    try:
        return etree.XMLSchema(etree.parse(str(path)))
    except (OSError, etree.XMLSchemaParseError, etree.XMLSyntaxError) as exc:
        raise ExportError(f"cannot load the schema {path}: {exc}") from None


def _to_lxml(element: ET.Element) -> etree._Element:
    """The same tree as lxml elements, built node by node (ElementTree's pure-Python
    serialiser was most of the export time)."""
    # scenariogeneration writes namespace declarations as plain attributes
    # ("xmlns:xsi", "xsi:noNamespaceSchemaLocation"); lxml wants them as an nsmap and
    # {namespace}name attributes.
    nsmap = {k.split(":", 1)[1]: v for k, v in element.attrib.items()
             if k.startswith("xmlns:")}
    attrib = {}
    for key, value in element.attrib.items():
        if key.startswith("xmlns:"):
            continue
        prefix, sep, local = key.partition(":")
        attrib[f"{{{nsmap[prefix]}}}{local}" if sep and prefix in nsmap else key] = value
    root = etree.Element(element.tag, attrib, nsmap=nsmap or None)
    root.text = element.text
    stack = [(element, root)]
    while stack:
        source, target = stack.pop()
        for child in source:
            node = etree.SubElement(target, child.tag, dict(child.attrib))
            node.text = child.text
            node.tail = child.tail
            stack.append((child, node))
    return root


def _validated_bytes(element: ET.Element, schema_name: str, what: str) -> bytes:
    """Serialise, validate against the XSD, return pretty-printed UTF-8 with declaration."""
    doc = _to_lxml(element)
    schema = _schema(schema_name)
    if not schema.validate(doc):
        errors = "; ".join(
            f"line {e.line}: {e.message}" for e in list(schema.error_log)[:3]
        )
        raise ExportError(f"{what} does not validate against {schema_name}: {errors}")
    out: bytes = etree.tostring(doc, pretty_print=True, xml_declaration=True,
                                encoding="UTF-8")
    return out


def _creation_date(manifest: Mapping[str, Any]) -> dt.datetime:
    value = manifest.get("created_at")
    if value is None:
        return DEFAULT_DATE
    if not isinstance(value, str):
        raise ExportError(f"manifest.created_at: expected an ISO 8601 string, got {value!r}")
    try:
        return dt.datetime.fromisoformat(value)
    except ValueError:
        raise ExportError(
            f"manifest.created_at: {value!r} is not an ISO 8601 date-time"
        ) from None


def _num(value: float) -> str:
    return repr(float(value))


def _vehicle(track: Track) -> xosc.Vehicle:
    box = xosc.BoundingBox(track.width, track.length, VEHICLE_HEIGHT,
                           0.0, 0.0, VEHICLE_HEIGHT / 2)
    track_width = track.width * 0.85
    front = xosc.Axle(MAX_STEERING, WHEEL_DIAMETER, track_width,
                      AXLE_FRACTION * track.length, WHEEL_DIAMETER / 2)
    rear = xosc.Axle(0.0, WHEEL_DIAMETER, track_width,
                     -AXLE_FRACTION * track.length, WHEEL_DIAMETER / 2)
    return xosc.Vehicle(track.id, xosc.VehicleCategory.car, box, front, rear,
                        MAX_SPEED, MAX_ACCELERATION, MAX_DECELERATION)


def _sim_time_trigger(name: str, value: float, point: str = "start") -> xosc.ValueTrigger:
    edge = xosc.ConditionEdge.rising if point == "stop" else xosc.ConditionEdge.none
    return xosc.ValueTrigger(
        name, 0.0, edge, xosc.SimulationTimeCondition(value, xosc.Rule.greaterOrEqual), point
    )


def _follow(track: Track, times: list[float]) -> xosc.ManeuverGroup:
    positions = [
        xosc.WorldPosition(x, y, h=psi)
        for x, y, psi in zip(track.x.tolist(), track.y.tolist(), track.psi.tolist(),
                             strict=True)
    ]
    trajectory = xosc.Trajectory(f"{track.id} trajectory", False)
    trajectory.add_shape(xosc.Polyline(times, positions))
    action = xosc.FollowTrajectoryAction(
        trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.absolute, 1.0, 0.0,
    )
    event = xosc.Event(f"{track.id} follows its trajectory", xosc.Priority.override)
    event.add_action(f"{track.id} follow trajectory", action)
    event.add_trigger(_sim_time_trigger(f"{track.id} starts", 0.0))
    maneuver = xosc.Maneuver(f"{track.id} maneuver")
    maneuver.add_event(event)
    group = xosc.ManeuverGroup(f"{track.id} maneuver group")
    group.add_actor(track.id)
    group.add_maneuver(maneuver)
    return group


def _properties(index: int, scenario: ConcreteScenario, row: Row) -> xosc.Properties:
    props = xosc.Properties()
    props.add_property("scengen.index", str(index))
    props.add_property("scengen.t0", _num(scenario.t[0]))
    if row.get("scenario_id") is not None:
        props.add_property("scengen.scenario_id", str(row["scenario_id"]))
    if scenario.seed is not None:
        props.add_property("scengen.seed", str(scenario.seed))
    for name, value in scenario.params.items():
        props.add_property(f"scengen.param.{name}", _num(value))
    return props


def scenario_xosc(
    scenario: ConcreteScenario,
    *,
    index: int = 0,
    row: Row | None = None,
    road_file: str = ROAD_FILE,
    date: dt.datetime = DEFAULT_DATE,
) -> bytes:
    """One scenario as a validated OpenSCENARIO 1.2 document (UTF-8 bytes)."""
    if not scenario.objects:
        raise ExportError("the scenario has no objects besides the ego")
    t0 = float(scenario.t[0])
    times = (scenario.t - t0).tolist()  # simulation time; unchanged when t0 == 0
    tracks = (scenario.ego, *scenario.objects)
    with _LOCK:
        entities = xosc.Entities()
        init = xosc.Init()
        act = xosc.Act("trajectories", _sim_time_trigger("act starts", 0.0))
        step = xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time,
                                       0.0)
        for track in tracks:
            entities.add_scenario_object(track.id, _vehicle(track))
            init.add_init_action(track.id, xosc.TeleportAction(
                xosc.WorldPosition(float(track.x[0]), float(track.y[0]),
                                   h=float(track.psi[0]))))
            init.add_init_action(track.id, xosc.AbsoluteSpeedAction(float(track.v[0]), step))
            act.add_maneuver_group(_follow(track, times))
        story = xosc.Story("scengen cut-in")
        story.add_act(act)
        storyboard = xosc.StoryBoard(init, _sim_time_trigger("end", times[-1], "stop"))
        storyboard.add_story(story)
        description = f"scengen scenario {index}"
        doc = xosc.Scenario(
            description, "scengen", xosc.ParameterDeclarations(), entities, storyboard,
            xosc.RoadNetwork(road_file), xosc.Catalog(), osc_minor_version=2,
            creation_date=date,
            header_properties=_properties(index, scenario, row or {}),
        )
        element = doc.get_element()
        return _validated_bytes(element, OSC_XSD, f"scenario {index} (.xosc)")


@dataclass
class RoadExtent:
    """What the shared road has to cover (m), grown scenario by scenario."""

    lane_width: float
    x_min: float = math.inf
    x_max: float = -math.inf
    y_min: float = 0.0
    y_max: float = 0.0

    def add(self, scenario: ConcreteScenario) -> None:
        for track in (scenario.ego, *scenario.objects):
            half = track.length / 2
            self.x_min = min(self.x_min, float(np.min(track.x)) - half)
            self.x_max = max(self.x_max, float(np.max(track.x)) + half)
            self.y_min = min(self.y_min, float(np.min(track.y)))
            self.y_max = max(self.y_max, float(np.max(track.y)))

    def lanes(self) -> tuple[int, int]:
        """Lanes left and right of the ego lane (>= 1 each) holding every vehicle centre."""
        w = self.lane_width
        n_left = max(1, math.floor(self.y_max / w + 0.5))
        n_right = max(1, math.floor(-self.y_min / w + 0.5))
        return n_left, n_right

    def x_range(self) -> tuple[float, float]:
        return (float(math.floor(self.x_min - ROAD_MARGIN)),
                float(math.ceil(self.x_max + ROAD_MARGIN)))


def road_xodr(extent: RoadExtent) -> bytes:
    """The shared straight road as a validated OpenDRIVE 1.7 document (UTF-8 bytes)."""
    n_left, n_right = extent.lanes()
    w = extent.lane_width
    x_start, x_end = extent.x_range()
    n_lanes = n_left + 1 + n_right
    y_ref = (n_left + 0.5) * w
    with _LOCK:  # the schema objects are shared; validate one document at a time
        road = xodr.create_road(xodr.Line(x_end - x_start), id=1, left_lanes=0,
                                right_lanes=n_lanes, lane_width=w)
        road.planview.set_start_point(x_start, y_ref, 0.0)
        odr = xodr.OpenDrive("scengen straight road", revMajor="1", revMinor="7")
        odr.add_road(road)
        odr.adjust_roads_and_lanes()
        element = odr.get_element()
        header = element.find("header")
        if header is None:  # pragma: no cover - scenariogeneration always writes one
            raise ExportError("scenariogeneration wrote an OpenDRIVE file without a header")
        header.attrib.pop("date", None)  # wall-clock time: not deterministic
        header.set("north", _num(y_ref))
        header.set("south", _num(y_ref - n_lanes * w))
        header.set("west", _num(x_start))
        header.set("east", _num(x_end))
        return _validated_bytes(element, ODR_XSD, f"the road ({ROAD_FILE})")


def _lane_width(scenario: ConcreteScenario, index: int) -> float:
    """``params["lane_width"]``, else ``provenance["lane_width"]`` (where the sampler's
    builder records it), else ``DEFAULT_LANE_WIDTH`` (m)."""
    if "lane_width" in scenario.params:
        value: Any = scenario.params["lane_width"]
        where = "params.lane_width"
    elif "lane_width" in scenario.provenance:
        value = scenario.provenance["lane_width"]
        where = "provenance.lane_width"
    else:
        return DEFAULT_LANE_WIDTH
    if (isinstance(value, bool) or not isinstance(value, int | float)
            or not math.isfinite(value) or value <= 0):
        raise ExportError(f"item {index}: {where} must be a number > 0 m, got {value!r}")
    return float(value)


def _zinfo(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.create_system = 3  # unix, so that the permission bits mean the same everywhere
    info.external_attr = ZIP_MODE << 16
    return info


def scenario_file_name(index: int) -> str:
    return f"scenario_{index:0{INDEX_DIGITS}d}.xosc"


def write_xosc_zip(items: Iterator[Item], manifest: Mapping[str, Any], path: Path) -> None:
    """Stream the scenarios into a scratch zip, then assemble the final sorted zip."""
    if "export" in manifest:
        raise ExportError("manifest: the key 'export' is reserved for the xosc export")
    date = _creation_date(manifest)
    scratch_zip = path.with_name(path.name + ".scenarios")
    scratch_csv = path.with_name(path.name + ".csv")
    extent: RoadExtent | None = None
    count = 0
    try:
        with zipfile.ZipFile(scratch_zip, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zs, \
                scratch_csv.open("w", encoding="utf-8", newline="") as fh:
            index_writer = CsvRowWriter(fh, lead=("file",))
            for index, scenario, _summary, row in items:
                if index >= 10**INDEX_DIGITS:
                    raise ExportError(
                        f"item {index}: the xosc export holds at most {10**INDEX_DIGITS} "
                        "scenarios; split the catalogue"
                    )
                width = _lane_width(scenario, index)
                if extent is None:
                    extent = RoadExtent(lane_width=width)
                elif width != extent.lane_width:
                    raise ExportError(
                        f"item {index}: lane_width {width} m differs from the catalogue's "
                        f"{extent.lane_width} m; one xosc export shares one road"
                    )
                extent.add(scenario)
                name = scenario_file_name(index)
                try:
                    data = scenario_xosc(scenario, index=index, row=row, date=date)
                except ExportError as exc:
                    raise ExportError(f"item {index}: {exc}") from None
                zs.writestr(name, data)
                index_writer.write(index, row, (name,))
                count += 1
        assert extent is not None  # an empty catalogue raised in the item stream
        road = road_xodr(extent)
        n_left, n_right = extent.lanes()
        x_start, x_end = extent.x_range()
        full_manifest = dict(manifest)
        full_manifest["export"] = {
            "format": "xosc",
            "n_scenarios": count,
            "openscenario": "1.2",
            "opendrive": "1.7",
            "road_file": ROAD_FILE,
            "index_file": INDEX_FILE,
            "scenario_files": f"scenario_<index, {INDEX_DIGITS} digits>.xosc",
            "lane_width": extent.lane_width,
            "lanes_left_of_ego": n_left,
            "lanes_right_of_ego": n_right,
            "road_x_range": [x_start, x_end],
            "frame": "scengen road frame = OpenSCENARIO world frame: x along the road, "
                     "y left, heading counter-clockwise from +x, z up; ego lane centre y = 0",
            "reference_point": "vehicle bounding-box centre (BoundingBox Center x = y = 0)",
            "time": "vertex time = scenario time - t[0] (simulation starts at the first "
                    "step); Timing absolute, scale 1, offset 0; t[0] in the scengen.t0 "
                    "header property",
        }
        with zipfile.ZipFile(path, "w") as zf:
            info = _zinfo(INDEX_FILE)
            info.file_size = os.path.getsize(scratch_csv)
            with scratch_csv.open("rb") as src, zf.open(info, "w") as dst:
                while chunk := src.read(1 << 20):
                    dst.write(chunk)
            zf.writestr(_zinfo(MANIFEST_FILE), dumps(full_manifest, indent=2) + "\n")
            zf.writestr(_zinfo(ROAD_FILE), road)
            with zipfile.ZipFile(scratch_zip) as zs:
                for entry in zs.infolist():  # written in index order = name order
                    zf.writestr(_zinfo(entry.filename), zs.read(entry))
    finally:
        for scratch in (scratch_zip, scratch_csv):
            if scratch.exists():
                scratch.unlink()
