"""OpenSCENARIO 1.2 documents of one cut-in: the two modes, the logical scenario, its parts.

Reference point. OpenSCENARIO positions are a vehicle's reference point; players such as
esmini and CARLA take it to be the rear axle and draw the bounding box ``BoundingBox/Center``
ahead of it. scengen's positions are box centres, so every vehicle gets its rear axle at
``REAR_AXLE_FRACTION`` * length behind the box centre (``RearAxle/positionX`` = 0,
``BoundingBox/Center/x`` = 0.3 L, ``FrontAxle/positionX`` = 0.6 L) and every position
written is the rear axle: ``(x, y) - 0.3 L (cos psi, sin psi)``.

Modes (``MODES``):

``replay``
    Both vehicles follow their exact trajectories (one polyline vertex per time step,
    absolute timing from simulation time 0). For visual checks and for comparing players.
``test``
    The ego is the system under test: ``Properties/Property type=ego_vehicle`` (the role
    CARLA ScenarioRunner looks for), an initial position and speed, no action (it keeps its
    speed unless a controller takes over). Nothing the cutter does depends on the ego: it
    follows its own trajectory from simulation time 0 (timing relative to that start,
    positions relative to where it starts), so the cut-in happens at the scenario's own
    times whatever the ego does, and after the scenario's end it keeps its last speed
    along its lane (``continued``: one more polyline vertex at the time limit), so that a
    slower ego still meets it. The
    run stops (``stop_trigger_test``) on a collision; once the scenario's duration has passed
    and the conflict is over (``conflict_over``: the ego not faster than the cutter, or
    closing on it with contact beyond the follow horizon, or the cutter out of the ego's
    path, or the ego ahead of it and not slower); or at the time limit,
    ``STOP_SLACK`` s after the scenario's duration. The road (``reach_of_test_run``) is long
    enough for any vehicle within its performance limits until the time limit.

``replay`` stops on a collision, when the trajectories end (the scenario's own end:
scengen's builder ends a scenario once the conflict is resolved) or at that end's time.
"""

from __future__ import annotations

import datetime as dt
import importlib
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from lxml import etree

from datasets import PARAM_DOCS, PARAM_NAMES, PARAM_UNITS
from riskcore import ConcreteScenario, Track
from riskcore.criticality import CriticalitySettings

MODES: tuple[str, ...] = ("test", "replay")
DEFAULT_MODE = "test"

#: the rear axle (reference point) lies this fraction of the length behind the box centre
REAR_AXLE_FRACTION = 0.3
#: vehicle properties scengen does not model (m, rad, m/s, m/s^2)
VEHICLE_HEIGHT = 1.5
WHEEL_DIAMETER = 0.7
MAX_STEERING = 0.5
MAX_SPEED = 70.0
MAX_ACCELERATION = 10.0
MAX_DECELERATION = 10.0
#: the ScenarioRunner role of the system under test
EGO_ROLE = "ego_vehicle"
#: test mode: the run's time limit, s after the scenario's duration (a reacting ego may
#: resolve the conflict later than the scripted one)
STOP_SLACK = 30.0
#: test mode: a conflict whose contact lies further ahead than this (s, time to collision)
#: is over (riskcore's ``CriticalitySettings.follow_horizon``)
FOLLOW_HORIZON = CriticalitySettings().follow_horizon
#: esmini merges polyline vertices closer than 0.1 m (its default ``--traj_filter``);
#: vertices are thinned to at least this spacing (m) so that no player drops any
MIN_VERTEX_SPACING = 0.12
EGO = "ego"


def num(value: float) -> str:
    """Shortest round-trip text of a float (``INF``/``-INF``/``NaN`` for non-finite)."""
    value = float(value)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(value)


def reference_points(track: Track) -> tuple[np.ndarray, np.ndarray]:
    """Rear-axle positions (m) of a track whose x, y are box centres."""
    back = REAR_AXLE_FRACTION * track.length
    return track.x - back * np.cos(track.psi), track.y - back * np.sin(track.psi)


def thinned(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the vertices to keep so that consecutive ones are at least
    ``MIN_VERTEX_SPACING`` apart (the first and the last always kept). Every vertex of a
    vehicle faster than ``MIN_VERTEX_SPACING / dt`` is kept."""
    n = x.shape[0]
    step = np.hypot(np.diff(x), np.diff(y))
    if n <= 2 or step.min() >= MIN_VERTEX_SPACING:
        return np.arange(n)
    keep = [0]
    for i in range(1, n - 1):
        if math.hypot(x[i] - x[keep[-1]], y[i] - y[keep[-1]]) >= MIN_VERTEX_SPACING:
            keep.append(i)
    last = n - 1
    if len(keep) > 1 and math.hypot(x[last] - x[keep[-1]],
                                    y[last] - y[keep[-1]]) < MIN_VERTEX_SPACING:
        keep.pop()
    keep.append(last)
    return np.asarray(keep)


def run_end_and_limit(scenario: ConcreteScenario) -> tuple[float, float]:
    """(end, limit) of a ``test`` run in simulation time (s): the scenario's duration,
    from which a resolved conflict stops the run, and the time limit."""
    end = float(scenario.t[-1] - scenario.t[0])
    return end, end + STOP_SLACK


def continued(track: Track, t: np.ndarray, limit: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The track's rear axles (time from its first step, x, y, heading) plus one vertex at
    simulation time ``limit``: after the scenario's end it keeps its last speed along its
    lane (+x, or -x for a track that ends heading back; its last y). The builder's cutters
    end straight (heading 0), so for them this is their last velocity. No vertex is added
    when it would lie less than ``MIN_VERTEX_SPACING`` away: a vehicle at rest stays."""
    x, y = reference_points(track)
    times = t - t[0]
    span = limit - float(times[-1])
    reach = float(track.v[-1]) * span
    if span <= 0 or abs(reach) < MIN_VERTEX_SPACING:
        return times, x, y, track.psi
    back = math.cos(float(track.psi[-1])) < 0
    return (np.append(times, limit), np.append(x, x[-1] + (-reach if back else reach)),
            np.append(y, y[-1]), np.append(track.psi, math.pi if back else 0.0))


def reach_of_test_run(scenario: ConcreteScenario) -> tuple[float, float]:
    """The x interval (m, box ends) a ``test`` run can reach by its time limit: every
    vehicle from where it starts at up to ``MAX_SPEED`` forwards, and the cutters to the
    end of their continued trajectories (``continued``; backwards for one heading back)."""
    _, limit = run_end_and_limit(scenario)
    lo, hi = math.inf, -math.inf
    for track in (scenario.ego, *scenario.objects):
        half = track.length / 2
        start = float(track.x[0])
        lo = min(lo, start - half)
        hi = max(hi, start + MAX_SPEED * limit + half)
        if track is not scenario.ego:
            _, x, _, psi = continued(track, scenario.t, limit)
            back = REAR_AXLE_FRACTION * track.length
            end = float(x[-1]) + back * math.cos(float(psi[-1]))  # the box centre
            lo, hi = min(lo, end - half), max(hi, end + half)
    return lo, hi


# ----------------------------------------------------------------------------- XML helpers


def el(parent: etree._Element | None, tag: str, **attrib: str) -> etree._Element:
    if parent is None:
        return etree.Element(tag, attrib)
    return etree.SubElement(parent, tag, attrib)


def file_header(root: etree._Element, description: str, date: dt.datetime,
                properties: Mapping[str, str] | None = None) -> None:
    header = el(root, "FileHeader", author="scengen", date=date.isoformat(),
                description=description, revMajor="1", revMinor="2")
    if properties:
        props = el(header, "Properties")
        for name, value in properties.items():
            el(props, "Property", name=name, value=value)


@dataclass(frozen=True)
class Declaration:
    """One ParameterDeclaration: name, OpenSCENARIO type, value text, unit and meaning."""

    name: str
    kind: str  # double | string | boolean | integer
    value: str
    unit: str
    doc: str


def declare(parent: etree._Element, declarations: Iterable[Declaration]) -> None:
    """``ParameterDeclarations`` with a comment giving each parameter's unit and meaning."""
    decls = el(parent, "ParameterDeclarations")
    for d in declarations:
        unit = f" [{d.unit}]" if d.unit else ""
        decls.append(etree.Comment(f" {d.name}{unit}: {d.doc} ".replace("--", "- -")))
        el(decls, "ParameterDeclaration", name=d.name, parameterType=d.kind, value=d.value)


def criticality_fields() -> dict[str, tuple[str, str, str]]:
    """``riskcore.criticality.CRITICALITY_FIELDS`` as name -> (unit, kind, doc); empty
    while that module is not installed."""
    try:
        module = importlib.import_module("riskcore.criticality")
    except ImportError:
        return {}
    fields = getattr(module, "CRITICALITY_FIELDS", {})
    out: dict[str, tuple[str, str, str]] = {}
    for name, spec in fields.items():
        unit = str(getattr(spec, "unit", "") or "")
        kind = str(getattr(spec, "kind", "float"))
        doc = str(getattr(spec, "doc", "") or "")
        out[str(name)] = (unit if unit != "-" else "", kind, doc)
    return out


_KINDS = {"float": "double", "bool": "boolean", "str": "string", "int": "integer"}


def _value_text(value: Any, kind: str) -> str:
    if kind == "boolean":
        return "true" if value else "false"
    if kind == "double":
        return num(value)
    return str(value)


def scenario_declarations(scenario: ConcreteScenario, row: Mapping[str, Any]) -> list[Declaration]:
    """The cut-in parameters, TTC and the criticality fields present in ``row``."""
    out: list[Declaration] = []
    for name in PARAM_NAMES:
        if name in scenario.params:
            out.append(Declaration(name, "double", num(scenario.params[name]),
                                   PARAM_UNITS[name], PARAM_DOCS[name]))
    if row.get("ttc") is not None:
        out.append(Declaration("ttc", "double", num(row["ttc"]), "s",
                               "time to collision gap / dv at the crossing moment "
                               "(INF: not closing)"))
    for name, (unit, kind, doc) in criticality_fields().items():
        value = row.get(name)
        if value is None:
            continue
        osc_kind = _KINDS.get(kind, "string")
        if osc_kind == "double" and isinstance(value, str):
            osc_kind = "string"
        out.append(Declaration(name, osc_kind, _value_text(value, osc_kind), unit, doc))
    return out


# ------------------------------------------------------------------------------ entities


def vehicle(parent: etree._Element, name: str, length: str, width: str, bb_x: str,
            wheelbase: str, *, ego_role: bool) -> None:
    """A car whose reference point is its rear axle; numbers as text (may be ``$refs``)."""
    obj = el(parent, "ScenarioObject", name=name)
    veh = el(obj, "Vehicle", name=name, vehicleCategory="car")
    box = el(veh, "BoundingBox")
    el(box, "Center", x=bb_x, y="0.0", z=num(VEHICLE_HEIGHT / 2))
    el(box, "Dimensions", width=width, length=length, height=num(VEHICLE_HEIGHT))
    el(veh, "Performance", maxSpeed=num(MAX_SPEED), maxAcceleration=num(MAX_ACCELERATION),
       maxDeceleration=num(MAX_DECELERATION))
    axles = el(veh, "Axles")
    wheel = {"wheelDiameter": num(WHEEL_DIAMETER), "positionZ": num(WHEEL_DIAMETER / 2)}
    track_width = width if width.startswith("$") else num(0.85 * float(width))
    el(axles, "FrontAxle", maxSteering=num(MAX_STEERING), trackWidth=track_width,
       positionX=wheelbase, **wheel)
    el(axles, "RearAxle", maxSteering="0.0", trackWidth=track_width, positionX="0.0", **wheel)
    props = el(veh, "Properties")
    # esmini: take headings along a polyline segment by segment instead of blending them
    # at the corners (which lags by about yaw rate * step / 2)
    el(props, "Property", name="plineInterpolation", value="segment")
    if ego_role:
        el(props, "Property", name="type", value=EGO_ROLE)


def world_position(parent: etree._Element, x: str, y: str, h: str) -> None:
    pos = el(parent, "Position")
    el(pos, "WorldPosition", x=x, y=y, z="0.0", h=h)


def teleport_and_speed(private: etree._Element, x: str, y: str, h: str, v: str) -> None:
    action = el(private, "PrivateAction")
    world_position(el(action, "TeleportAction"), x, y, h)
    action = el(private, "PrivateAction")
    speed = el(el(action, "LongitudinalAction"), "SpeedAction")
    el(speed, "SpeedActionDynamics", dynamicsShape="step", value="0.0",
       dynamicsDimension="time")
    el(el(speed, "SpeedActionTarget"), "AbsoluteTargetSpeed", value=v)


def trajectory(parent: etree._Element, name: str, times: np.ndarray, x: np.ndarray,
               y: np.ndarray, h: np.ndarray, *, relative_to: str | None) -> etree._Element:
    """A polyline ``Trajectory``: absolute ``WorldPosition``s, or ``RelativeWorldPosition``s
    (dx, dy from ``relative_to``'s position when the action starts; heading absolute)."""
    traj = el(parent, "Trajectory", name=name, closed="false")
    line = el(el(traj, "Shape"), "Polyline")
    keep = thinned(x, y)
    times, x, y, h = times[keep], x[keep], y[keep], h[keep]
    for ti, xi, yi, hi in zip(times.tolist(), x.tolist(), y.tolist(), h.tolist(), strict=True):
        pos = el(el(line, "Vertex", time=repr(ti)), "Position")
        if relative_to is None:
            el(pos, "WorldPosition", x=repr(xi), y=repr(yi), z="0.0", h=repr(hi))
        else:
            rel = el(pos, "RelativeWorldPosition", entityRef=relative_to, dx=repr(xi),
                     dy=repr(yi), dz="0.0")
            el(rel, "Orientation", type="absolute", h=repr(hi), p="0.0", r="0.0")
    return traj


def follow(event: etree._Element, action_name: str, timing: str) -> etree._Element:
    """A FollowTrajectoryAction under ``event``; returns its ``TrajectoryRef`` to fill."""
    action = el(event, "Action", name=action_name)
    follow_action = el(el(el(action, "PrivateAction"), "RoutingAction"), "FollowTrajectoryAction")
    ref = el(follow_action, "TrajectoryRef")
    el(el(follow_action, "TimeReference"), "Timing", domainAbsoluteRelative=timing,
       scale="1.0", offset="0.0")
    el(follow_action, "TrajectoryFollowingMode", followingMode="position")
    return ref


def condition(group: etree._Element, name: str, edge: str = "none") -> etree._Element:
    return el(group, "Condition", name=name, delay="0.0", conditionEdge=edge)


def sim_time_condition(group: etree._Element, name: str, value: str,
                       edge: str = "none") -> None:
    by_value = el(condition(group, name, edge), "ByValueCondition")
    el(by_value, "SimulationTimeCondition", value=value, rule="greaterOrEqual")


def entity_condition(group: etree._Element, name: str, triggering: str,
                     edge: str = "none") -> etree._Element:
    by_entity = el(condition(group, name, edge), "ByEntityCondition")
    ents = el(by_entity, "TriggeringEntities", triggeringEntitiesRule="any")
    el(ents, "EntityRef", entityRef=triggering)
    return el(by_entity, "EntityCondition")


def stop_trigger_replay(storyboard: etree._Element, objects: Iterable[str],
                        end_time: str) -> None:
    """``replay``: stop on a collision of the ego with an object, once every object's
    trajectory is done (the scenario's own end), or at simulation time ``end_time``."""
    names = list(objects)
    trig = el(storyboard, "StopTrigger")
    _collisions(trig, names)
    done = el(trig, "ConditionGroup")
    for name in names:
        state = el(condition(done, f"{name} trajectory done"), "ByValueCondition")
        el(state, "StoryboardElementStateCondition", storyboardElementType="event",
           storyboardElementRef=event_name(name), state="completeState")
    sim_time_condition(el(trig, "ConditionGroup"), "end", end_time)


def _collisions(trig: etree._Element, names: list[str]) -> None:
    for name in names:
        cond = entity_condition(el(trig, "ConditionGroup"), f"ego collides with {name}", EGO)
        el(el(cond, "CollisionCondition"), "EntityRef", entityRef=name)


def stop_trigger_test(storyboard: etree._Element, objects: Iterable[str], end_time: str,
                      limit: str) -> None:
    """``test``: stop on a collision of the ego with an object; from simulation time
    ``end_time`` on, once the conflict is over (``conflict_over``); or at ``limit``."""
    names = list(objects)
    trig = el(storyboard, "StopTrigger")
    _collisions(trig, names)
    conflict_over(trig, names, end_time)
    sim_time_condition(el(trig, "ConditionGroup"), "time limit", limit)


def conflict_over(trig: etree._Element, names: list[str], end_time: str) -> None:
    """Condition groups that end a ``test`` run from ``end_time`` on: the conflict with
    every object is over in the same way, one of (as the builder's resolution and the
    closed-loop simulator take it):

    * the ego is not faster than the object (no gap to one ahead shrinks);
    * it closes on the object so slowly that contact lies more than ``FOLLOW_HORIZON``
      ahead (time to collision, box to box along the ego's heading);
    * no object overlaps the ego's path (lateral clearance box to box > 0);
    * the ego is ahead of the object (the object's time headway to it > 0) and not
      slower (the object does not catch up with it).
    """
    def group(label: str) -> etree._Element:
        out = el(trig, "ConditionGroup")
        sim_time_condition(out, f"scenario over ({label})", end_time)
        return out

    slower = group("not faster")
    for name in names:
        cond = entity_condition(slower, f"ego not faster than {name}", EGO)
        el(cond, "RelativeSpeedCondition", entityRef=name, rule="lessOrEqual", value="0.0")
    slow = group("closing slowly")
    for name in names:
        cond = entity_condition(slow, f"contact with {name} beyond the follow horizon", EGO)
        ttc = el(cond, "TimeToCollisionCondition", freespace="true", rule="greaterThan",
                 value=num(FOLLOW_HORIZON), relativeDistanceType="longitudinal",
                 coordinateSystem="entity")
        el(el(ttc, "TimeToCollisionConditionTarget"), "EntityRef", entityRef=name)
    aside = group("out of the path")
    for name in names:
        cond = entity_condition(aside, f"{name} beside the ego's path", EGO)
        el(cond, "RelativeDistanceCondition", entityRef=name, freespace="true",
           relativeDistanceType="lateral", rule="greaterThan", value="0.0",
           coordinateSystem="entity")
    ahead = group("ahead")
    for name in names:
        cond = entity_condition(ahead, f"ego not slower than {name}", EGO)
        el(cond, "RelativeSpeedCondition", entityRef=name, rule="greaterOrEqual", value="0.0")
        # a positive time headway of the object to the ego: the ego is ahead of it
        cond = entity_condition(ahead, f"ego ahead of {name}", name)
        el(cond, "TimeHeadwayCondition", entityRef=EGO, freespace="true", rule="greaterThan",
           value="0.0", coordinateSystem="entity", relativeDistanceType="longitudinal")


def event_name(obj: str) -> str:
    return f"{obj} manoeuvre"


def root_element() -> etree._Element:
    xsi = "http://www.w3.org/2001/XMLSchema-instance"
    root = etree.Element("OpenSCENARIO", nsmap={"xsi": xsi})
    root.set(f"{{{xsi}}}noNamespaceSchemaLocation", "OpenScenario.xsd")
    return root


# ------------------------------------------------------------------------------ documents


def _vehicle_of(parent: etree._Element, track: Track, *, ego_role: bool) -> None:
    vehicle(parent, track.id, num(track.length), num(track.width),
            num(REAR_AXLE_FRACTION * track.length), num(2 * REAR_AXLE_FRACTION * track.length),
            ego_role=ego_role)


def scenario_document(
    scenario: ConcreteScenario,
    *,
    mode: str,
    description: str,
    date: dt.datetime,
    properties: Mapping[str, str],
    declarations: Iterable[Declaration],
    road_file: str,
) -> etree._Element:
    """One concrete scenario as an OpenSCENARIO 1.2 tree in ``mode`` (see the module doc)."""
    if mode not in MODES:
        raise ValueError(f"mode: unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    t = scenario.t
    t0 = float(t[0])
    duration = float(t[-1]) - t0
    end, limit = run_end_and_limit(scenario)
    root = root_element()
    file_header(root, description, date, properties)
    declare(root, declarations)
    el(root, "CatalogLocations")
    el(el(root, "RoadNetwork"), "LogicFile", filepath=road_file)
    entities = el(root, "Entities")
    tracks = (scenario.ego, *scenario.objects)
    for track in tracks:
        _vehicle_of(entities, track, ego_role=(mode == "test" and track is scenario.ego))
    storyboard = el(root, "Storyboard")
    actions = el(el(storyboard, "Init"), "Actions")
    for track in tracks:
        x, y = reference_points(track)
        teleport_and_speed(el(actions, "Private", entityRef=track.id), num(x[0]), num(y[0]),
                           num(track.psi[0]), num(track.v[0]))
    story = el(storyboard, "Story", name="scengen cut-in")
    act = el(story, "Act", name=mode)
    followers = scenario.objects if mode == "test" else tracks
    for track in followers:
        group = el(act, "ManeuverGroup", maximumExecutionCount="1",
                   name=f"{track.id} maneuver group")
        el(el(group, "Actors", selectTriggeringEntities="false"), "EntityRef",
           entityRef=track.id)
        maneuver = el(group, "Maneuver", name=f"{track.id} maneuver")
        event = el(maneuver, "Event", name=event_name(track.id), priority="override",
                   maximumExecutionCount="1")
        x, y = reference_points(track)
        if mode == "replay":
            ref = follow(event, f"{track.id} follows its trajectory", "absolute")
            trajectory(ref, f"{track.id} trajectory", t - t0, x, y, track.psi,
                       relative_to=None)
            start = el(event, "StartTrigger")
            sim_time_condition(el(start, "ConditionGroup"), f"{track.id} starts", "0.0")
        else:
            times, xs, ys, hs = continued(track, t, limit)
            ref = follow(event, f"{track.id} follows its trajectory", "relative")
            trajectory(ref, f"{track.id} trajectory", times, xs - xs[0], ys - ys[0], hs,
                       relative_to=track.id)
            start = el(event, "StartTrigger")
            sim_time_condition(el(start, "ConditionGroup"), f"{track.id} starts", "0.0")
    start = el(act, "StartTrigger")
    sim_time_condition(el(start, "ConditionGroup"), "act starts", "0.0")
    names = [o.id for o in scenario.objects]
    if mode == "replay":
        stop_trigger_replay(storyboard, names, num(duration))
    else:
        stop_trigger_test(storyboard, names, num(end), num(limit))
    return root


# ------------------------------------------------------------ the catalogue as one scenario

#: the Trajectory catalogue of the logical scenario: its name and directory
TRAJECTORY_CATALOG = "scengen_cutter_trajectories"
CATALOG_DIR = "catalogs"
#: parameters that place the vehicles and start the cutter in the logical scenario,
#: (name, type, unit, meaning); values per tuple from ``control_values``
CONTROL_PARAMETERS: tuple[tuple[str, str, str, str], ...] = (
    *((f"{v}_{name}", "double", unit, f"{v}: {doc}") for v in (EGO, "cutter")
      for name, unit, doc in (
          ("length", "m", "bounding-box length"),
          ("width", "m", "bounding-box width"),
          ("bb_x", "m", "box centre ahead of the rear axle (0.3 length)"),
          ("wheelbase", "m", "front axle ahead of the rear axle (0.6 length)"),
          ("x0", "m", "initial rear-axle x"),
          ("y0", "m", "initial rear-axle y"),
          ("h0", "rad", "initial heading"),
          ("v0", "m/s", "initial speed"),
      )),
    ("cutter_trajectory", "string", "", f"entry of the {TRAJECTORY_CATALOG} catalogue"),
    ("end_time", "double", "s", "the scenario's duration: from then on a resolved conflict "
     "ends the run (simulation time)"),
    ("stop_time", "double", "s", f"time limit of the run: end_time + {STOP_SLACK:g} s "
     "(simulation time)"),
)


def control_values(scenario: ConcreteScenario, entry: str) -> dict[str, str]:
    """The values of ``CONTROL_PARAMETERS`` for one single-cutter scenario."""
    out: dict[str, str] = {}
    for prefix, track in ((EGO, scenario.ego), ("cutter", scenario.objects[0])):
        x, y = reference_points(track)
        out[f"{prefix}_length"] = num(track.length)
        out[f"{prefix}_width"] = num(track.width)
        out[f"{prefix}_bb_x"] = num(REAR_AXLE_FRACTION * track.length)
        out[f"{prefix}_wheelbase"] = num(2 * REAR_AXLE_FRACTION * track.length)
        out[f"{prefix}_x0"] = num(x[0])
        out[f"{prefix}_y0"] = num(y[0])
        out[f"{prefix}_h0"] = num(track.psi[0])
        out[f"{prefix}_v0"] = num(track.v[0])
    end, limit = run_end_and_limit(scenario)
    out["cutter_trajectory"] = entry
    out["end_time"] = num(end)
    out["stop_time"] = num(limit)
    return out


def cutter_trajectory(parent: etree._Element, scenario: ConcreteScenario,
                      name: str) -> etree._Element:
    """The cutter's test-mode trajectory (relative to where it starts, continued)."""
    _, limit = run_end_and_limit(scenario)
    times, x, y, h = continued(scenario.objects[0], scenario.t, limit)
    return trajectory(parent, name, times, x - x[0], y - y[0], h, relative_to="cutter")


def logical_document(*, description: str, date: dt.datetime,
                     declarations: Iterable[Declaration], road_file: str) -> etree._Element:
    """The parameterised test-mode scenario of a single-cutter catalogue: every value that
    differs between the scenarios is a ``$parameter`` (defaults: the first scenario)."""
    root = root_element()
    file_header(root, description, date)
    declare(root, declarations)
    locations = el(root, "CatalogLocations")
    el(el(locations, "TrajectoryCatalog"), "Directory", path=CATALOG_DIR)
    el(el(root, "RoadNetwork"), "LogicFile", filepath=road_file)
    entities = el(root, "Entities")
    for name in (EGO, "cutter"):
        vehicle(entities, name, f"${name}_length", f"${name}_width", f"${name}_bb_x",
                f"${name}_wheelbase", ego_role=(name == EGO))
    storyboard = el(root, "Storyboard")
    actions = el(el(storyboard, "Init"), "Actions")
    for name in (EGO, "cutter"):
        teleport_and_speed(el(actions, "Private", entityRef=name), f"${name}_x0",
                           f"${name}_y0", f"${name}_h0", f"${name}_v0")
    story = el(storyboard, "Story", name="scengen cut-in")
    act = el(story, "Act", name="test")
    group = el(act, "ManeuverGroup", maximumExecutionCount="1", name="cutter maneuver group")
    el(el(group, "Actors", selectTriggeringEntities="false"), "EntityRef", entityRef="cutter")
    event = el(el(group, "Maneuver", name="cutter maneuver"), "Event",
               name=event_name("cutter"), priority="override", maximumExecutionCount="1")
    ref = follow(event, "cutter follows its trajectory", "relative")
    el(ref, "CatalogReference", catalogName=TRAJECTORY_CATALOG, entryName="$cutter_trajectory")
    start = el(event, "StartTrigger")
    sim_time_condition(el(start, "ConditionGroup"), "cutter starts", "0.0")
    start = el(act, "StartTrigger")
    sim_time_condition(el(start, "ConditionGroup"), "act starts", "0.0")
    stop_trigger_test(storyboard, ["cutter"], "$end_time", "$stop_time")
    return root
