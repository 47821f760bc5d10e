"""Run a system under test in esmini: the same cut-ins, the SUT driving the ego step by step
through esmini's C library (``libesminiLib``, loaded with :mod:`ctypes`).

esmini (https://github.com/esmini/esmini) is not a dependency: the user points scengen at
their own build of the library, ``library=`` or the environment variable
``SCENGEN_ESMINI_LIB`` (:func:`find_library`). docs/systems.md has the how-to and the
measured agreement with scengen's own simulator.

What :func:`simulate_esmini` does, per cut-in:

1. The scenarios are exported as OpenSCENARIO in ``test`` mode (:func:`app.exports.
   export_catalogue`; docs/exports.md): the cutter follows its sampled trajectory from
   simulation time 0 whatever the ego does, and keeps its last speed along its lane after
   it; the ego has no action; the road is long enough for any ego; esmini's own stop
   trigger ends the run on a collision, an over conflict or the time limit.
2. esmini loads the file (``SE_Init``, controllers of the file enabled: the ego has none)
   and is stepped with a fixed step ``settings.dt`` (``SE_StepDT``). Each step the adapter
   reads both vehicles' states (``SE_GetObjectState``: reference point, heading, speed,
   bounding-box offset; ``SE_GetObjectAcceleration`` for the cutter's acceleration), builds
   the SUT's :class:`riskcore.sut.Observations` from them as scengen's simulator does
   (box centres, the ego lane's frame, perception delay, sensor range, update period),
   asks the SUT (every ``settings.update_period``) and moves the ego.
3. The ego's longitudinal dynamics are scengen's vehicle model, the simulator's own
   kernel (:func:`riskcore.sut.ego_advance_with_onset`: the command clipped to
   ``[-a_brake_max, a_accel_max]``, reached at the jerk limit, no reversing; a SUT's
   ``command_onset`` honoured). esmini has no longitudinal dynamics for an externally
   driven object: it moves the ego along its lane
   by the speed reported for the step (``SE_ReportObjectSpeed``, applied over the next
   ``SE_StepDT``), so the adapter reports the step's mean speed (distance covered / dt)
   and esmini's ego lands where the vehicle model's does. The ego's own speed and
   acceleration in the observations are the model's (proprioception).
4. Contact is esmini's collision detection (``SE_CollisionDetection``,
   ``SE_GetObjectNumberOfCollisions``) at the step's end; its moment and the impact speed
   are refined inside the step by bisection on the states interpolated between the two
   steps (the rotated-box test, :func:`boxes_touch`). The margins (smallest gap, TTC,
   time headway from the perception moment on), the regulation's intrusion moment
   (``must_avoid``), the
   largest deceleration and jerk and the braking moment are those of
   :data:`riskcore.sut.RUN_FIELDS`, computed from esmini's states with the simulator's
   box geometry (:func:`riskcore.sut.box_clearance`, :func:`riskcore.sut.band_range`).
5. A run ends at contact; once the cutter's script is over and the conflict resolved,
   with scengen's rule on esmini's states (``settled``, ``left_behind``, ``no_conflict``:
   :mod:`riskcore.sut.simulate`), so that both simulators measure the same window; when
   esmini's stop trigger fires first (``end = "esmini_stop"``: the export's own rule, e.g.
   contact more than 60 s ahead, or its time limit 30 s after the scenario's duration); or
   at ``settings.t_max``.

The result is a :class:`riskcore.sut.RunBatch` like :func:`riskcore.sut.simulate`'s (the
Wagner risk fields NaN), plus :class:`EsminiDiagnostics` (how far esmini's ego drifted
from the vehicle model, steps where esmini's collision flag and the box test disagree).

esmini holds one scenario at a time per process (global state in the library): runs are
sequential, and a process-wide lock keeps threads from interleaving them.
"""

from __future__ import annotations

import ctypes
import math
import os
import tempfile
import threading
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from lxml import etree
from numpy.typing import ArrayLike, NDArray

from app.exports import build_manifest, export_catalogue
from riskcore import ConcreteScenario, FieldError
from riskcore.sut import (
    CutInBatch,
    Observations,
    RunBatch,
    SimSettings,
    SystemUnderTest,
    band_range,
    box_clearance,
    ego_advance_with_onset,
    must_avoid,
)

__all__ = [
    "END_NAMES",
    "ENV_VAR",
    "PROFILE_KEYS",
    "EsminiDiagnostics",
    "EsminiError",
    "EsminiLibrary",
    "EsminiResult",
    "adapter_document",
    "boxes_touch",
    "esmini_world",
    "find_library",
    "simulate_esmini",
]

#: the environment variable naming the user's esmini library
ENV_VAR = "SCENGEN_ESMINI_LIB"
#: how a run ends: scengen's names plus esmini's own stop trigger
END_NAMES = ("contact", "settled", "left_behind", "no_conflict", "t_max", "esmini_stop")
#: UN R157's perception of the cut-in (as riskcore.sut: a lateral move of this many m)
WANDERING_ZONE = 0.375
#: the regulation's moment: the cutter this far past the lane marking, m
INTRUSION_DEPTH = 0.3
#: "settled" (scengen's rule): the ego accelerates by at most this, m/s²
SETTLE_ACCEL = 0.1
#: the cutter drives straight when |sin(heading)| is below this (esmini's headings come
#: from polyline segments: exact 0 on the straight tail up to rounding)
STRAIGHT_SIN = 1e-6
_BISECT = 52  # bisection steps for the contact moment inside a step
#: the profiles' arrays: the ego's x (from its start), v, a; the cutter's centre (in the
#: ego's start frame), heading, speed, acceleration as esmini has them
PROFILE_KEYS = ("x", "v", "a", "cx", "cy", "cpsi", "cv", "ca")

_LOCK = threading.Lock()


class EsminiError(FieldError):
    """esmini cannot be used as asked: no library, a library that does not load, a scenario
    it rejects, or a bad argument. The message names the field."""


def find_library(library: str | os.PathLike[str] | None = None) -> Path:
    """The esmini shared library to use: ``library`` if given, else the file named by the
    environment variable ``SCENGEN_ESMINI_LIB``. An :class:`EsminiError` (field
    ``library``) when neither names an existing file."""
    if library is None:
        value = os.environ.get(ENV_VAR, "").strip()
        if not value:
            raise EsminiError(f"library: no esmini library given; set {ENV_VAR} to the path "
                              "of libesminiLib.so (esmini's shared library)",
                              field="library", problem="missing")
        path = Path(value).expanduser()
        where = f"{ENV_VAR}={value!r}"
    else:
        path = Path(library).expanduser()
        where = f"library={str(library)!r}"
    if not path.is_file():
        raise EsminiError(f"library: {where} is not a file", field="library",
                          problem="not found", value=str(path))
    return path.resolve()


class _State(ctypes.Structure):
    """``SE_ScenarioObjectState`` of esminiLib.hpp (esmini 3.x)."""

    _fields_ = [
        ("id", ctypes.c_int), ("model_id", ctypes.c_int), ("ctrl_type", ctypes.c_int),
        ("timestamp", ctypes.c_double), ("x", ctypes.c_double), ("y", ctypes.c_double),
        ("z", ctypes.c_double), ("h", ctypes.c_double), ("p", ctypes.c_double),
        ("r", ctypes.c_double), ("roadId", ctypes.c_uint32), ("junctionId", ctypes.c_uint32),
        ("t", ctypes.c_double), ("laneId", ctypes.c_int), ("laneOffset", ctypes.c_double),
        ("s", ctypes.c_double), ("speed", ctypes.c_double),
        ("centerOffsetX", ctypes.c_double), ("centerOffsetY", ctypes.c_double),
        ("centerOffsetZ", ctypes.c_double), ("width", ctypes.c_double),
        ("length", ctypes.c_double), ("height", ctypes.c_double),
        ("objectType", ctypes.c_int), ("objectCategory", ctypes.c_int),
        ("wheel_angle", ctypes.c_double), ("wheel_rot", ctypes.c_double),
        ("visibilityMask", ctypes.c_int),
    ]


@dataclass(frozen=True)
class VehicleState:
    """One vehicle as esmini has it, in scengen's terms: box centre (m), heading (rad,
    in (-pi, pi]), speed (m/s), acceleration (m/s²)."""

    x: float
    y: float
    h: float
    v: float
    a: float


class EsminiLibrary:
    """The C API of one esmini shared library (the calls the adapter needs, typed)."""

    _loaded: ClassVar[dict[Path, EsminiLibrary]] = {}

    def __init__(self, path: Path) -> None:
        try:
            lib = ctypes.CDLL(str(path))
        except OSError as exc:
            raise EsminiError(f"library: {path} does not load: {exc}", field="library",
                              problem="not loadable", value=str(path)) from None
        try:
            sig: dict[str, tuple[list[Any], Any]] = {
                "SE_Init": ([ctypes.c_char_p, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                             ctypes.c_int], ctypes.c_int),
                "SE_StepDT": ([ctypes.c_double], ctypes.c_int),
                "SE_Close": ([], None),
                "SE_GetQuitFlag": ([], ctypes.c_int),
                "SE_GetSimulationTime": ([], ctypes.c_double),
                "SE_GetIdByName": ([ctypes.c_char_p], ctypes.c_int),
                "SE_GetObjectState": ([ctypes.c_int, ctypes.POINTER(_State)], ctypes.c_int),
                "SE_GetObjectAcceleration": ([ctypes.c_int], ctypes.c_double),
                "SE_GetObjectNumberOfCollisions": ([ctypes.c_int], ctypes.c_int),
                "SE_GetObjectCollision": ([ctypes.c_int, ctypes.c_int], ctypes.c_int),
                "SE_ReportObjectSpeed": ([ctypes.c_int, ctypes.c_double], ctypes.c_int),
                "SE_CollisionDetection": ([ctypes.c_bool], None),
                "SE_SetOptionPersistent": ([ctypes.c_char_p], ctypes.c_int),
                "SE_SetLogFilePath": ([ctypes.c_char_p], None),
            }
            for name, (args, res) in sig.items():
                fn = getattr(lib, name)
                fn.argtypes = args
                fn.restype = res
        except AttributeError as exc:
            raise EsminiError(f"library: {path} is not esmini's library ({exc})",
                              field="library", problem="not esmini", value=str(path)) from None
        self.path = path
        self.lib = lib
        self._st = _State()
        # quiet and without a log file (a persistent option survives SE_Close)
        lib.SE_SetOptionPersistent(b"disable_stdout")

    @classmethod
    def load(cls, path: Path) -> EsminiLibrary:
        """The library at ``path``, loaded once per process."""
        if path not in cls._loaded:
            cls._loaded[path] = cls(path)
        return cls._loaded[path]

    def open(self, xosc: Path, ego_name: str, cutter_name: str) -> tuple[int, int]:
        """Load a scenario (collision detection on); returns the ids of ego and cutter."""
        self.lib.SE_SetLogFilePath(b"")
        if self.lib.SE_Init(str(xosc).encode(), 0, 0, 0, 0) != 0:
            raise EsminiError(f"scenarios: esmini could not load {xosc.name}",
                              field="scenarios", problem="rejected by esmini")
        self.lib.SE_CollisionDetection(True)
        ego = self.lib.SE_GetIdByName(ego_name.encode())
        cutter = self.lib.SE_GetIdByName(cutter_name.encode())
        if ego < 0 or cutter < 0:
            self.lib.SE_Close()
            raise EsminiError(f"scenarios: esmini finds no {ego_name!r} and {cutter_name!r} "
                              f"in {xosc.name}", field="scenarios",
                              problem="no ego or cutter")
        return ego, cutter

    def state(self, obj: int, with_acc: bool = False) -> VehicleState:
        st = self._st
        if self.lib.SE_GetObjectState(obj, ctypes.byref(st)) != 0:
            raise RuntimeError(f"esmini: no state of object {obj}")
        c, s = math.cos(st.h), math.sin(st.h)
        x = st.x + st.centerOffsetX * c - st.centerOffsetY * s
        y = st.y + st.centerOffsetX * s + st.centerOffsetY * c
        h = math.atan2(s, c)
        a = float(self.lib.SE_GetObjectAcceleration(obj)) if with_acc else 0.0
        return VehicleState(x, y, h, float(st.speed), a)

    def collides(self, ego: int, other: int) -> bool:
        n = self.lib.SE_GetObjectNumberOfCollisions(ego)
        return any(self.lib.SE_GetObjectCollision(ego, k) == other for k in range(max(n, 0)))

    def report_speed(self, obj: int, v: float) -> None:
        self.lib.SE_ReportObjectSpeed(obj, v)

    def step(self, dt: float) -> bool:
        """Advance by dt; False when esmini did not (its stop trigger fired on the states
        of the previous step: it quits without moving anything)."""
        before = float(self.lib.SE_GetSimulationTime())
        if self.lib.SE_StepDT(dt) != 0:
            raise RuntimeError("esmini: SE_StepDT failed")
        moved = float(self.lib.SE_GetSimulationTime()) > before + 0.5 * dt
        return moved and not self.quit()

    def quit(self) -> bool:
        return bool(self.lib.SE_GetQuitFlag() == 1)

    def close(self) -> None:
        self.lib.SE_Close()


# ---------------------------------------------------------------------------- geometry

def _clearance(cut: VehicleState, ego_x: float, ego_y: float, ehl: float, ehw: float,
               chl: float, chw: float) -> float | None:
    """The free distance ahead of the ego's front to the cutter's box inside the ego's
    band (< 0: the boxes overlap), or None when the box is not in the band beside or
    ahead of the ego (scengen's ``min_gap`` counts only those): the simulator's
    :func:`riskcore.sut.box_clearance` on the states relative to the ego."""
    near, gap = box_clearance(cut.x - ego_x, cut.y - ego_y, cut.h, 0.0, ehl, ehw, chl, chw)
    return float(gap) if near else None


def boxes_touch(cut: VehicleState, ego_x: float, ego_y: float, ehl: float, ehw: float,
                chl: float, chw: float) -> bool:
    """The cutter's box overlaps the ego's (heading 0, centre ego_x, ego_y): its part
    inside the ego's band reaches between the ego's rear and front."""
    gap = _clearance(cut, ego_x, ego_y, ehl, ehw, chl, chw)
    return gap is not None and gap < 0.0


def _rel(cut: VehicleState, x0: float, y0: float) -> tuple[float, ...]:
    return cut.x - x0, cut.y - y0, cut.h, cut.v, cut.a


def _lerp_state(p: VehicleState, q: VehicleState, f: float) -> VehicleState:
    dh = math.atan2(math.sin(q.h - p.h), math.cos(q.h - p.h))
    return VehicleState(p.x + f * (q.x - p.x), p.y + f * (q.y - p.y), p.h + f * dh,
                        p.v + f * (q.v - p.v), p.a + f * (q.a - p.a))


# ------------------------------------------------------------------------------ results

@dataclass
class EsminiDiagnostics:
    """Per run: the largest distance between esmini's ego and the vehicle model's (m),
    the number of steps where esmini's collision flag and the box test on esmini's states
    disagree, and the number of steps run."""

    ego_drift: NDArray[np.float64]
    flag_box_disagree: NDArray[np.int64]
    steps: NDArray[np.int64]


@dataclass
class EsminiResult:
    """:func:`simulate_esmini`'s outcome: the runs (``RunBatch``; ``end`` may also be
    ``"esmini_stop"``) and the diagnostics."""

    runs: RunBatch
    diagnostics: EsminiDiagnostics


def _seeds(seeds: ArrayLike | int, n: int) -> NDArray[np.uint64]:
    """One seed per run as :func:`riskcore.sut.simulate` derives them from an int."""
    if isinstance(seeds, int | np.integer) and not isinstance(seeds, bool):
        if int(seeds) < 0:
            raise EsminiError(f"seeds: must be >= 0, got {seeds}", field="seeds")
        ss = np.random.SeedSequence(int(seeds))
        return np.asarray(ss.generate_state(n, dtype=np.uint64), dtype=np.uint64)
    arr = np.asarray(seeds)
    if arr.shape != (n,) or arr.dtype.kind not in "ui" or (
            arr.dtype.kind == "i" and np.any(arr < 0)):
        raise EsminiError(f"seeds: expected an int or {n} non-negative integers",
                          field="seeds")
    return np.asarray(arr, dtype=np.uint64)


class _Run:
    """One run's bookkeeping (the fields of RUN_FIELDS)."""

    def __init__(self) -> None:
        self.collided = False
        self.impact = 0.0
        self.t_contact = math.nan
        self.min_gap = math.inf
        self.min_ttc = math.inf
        self.min_thw = math.inf
        self.max_decel = 0.0
        self.max_jerk = 0.0
        self.t_brake = math.nan
        self.intr_prev = math.inf
        self.intr_t = math.nan
        self.intr_ttc = math.nan
        self.intr_vrel = math.nan
        self.end_time = math.nan
        self.end = "t_max"

    def intrusion(self, t0: float, dt: float, cut: VehicleState, ego_x: float, ego_y: float,
                  v_ego: float, ehl: float, chl: float, chw: float, at: float) -> None:
        """The regulation's moment: the cutter's inner edge ``at`` m from the ego lane's
        centre line (interpolated in the step from t0 to t0 + dt; dt = 0 at the start)."""
        dy = cut.y - ego_y
        inner = abs(dy) - (chl * abs(math.sin(cut.h)) + chw * abs(math.cos(cut.h)))
        if inner <= at and math.isnan(self.intr_t):
            prev = self.intr_prev
            f = (prev - at) / (prev - inner) if math.isfinite(prev) and prev > inner else 1.0
            clos = v_ego - cut.v * math.cos(cut.h)
            gap = cut.x - ego_x - ehl - chl
            self.intr_t = t0 + f * dt
            self.intr_vrel = clos
            self.intr_ttc = (gap / clos if gap > 0.0 else 0.0) if clos > 0.0 else math.inf
        self.intr_prev = inner


def _observations(t: float, v: float, a: float, batch: CutInBatch, cut: VehicleState,
                  ego_x: float, ego_y: float, dy0: float, active: bool, sensor_range: float,
                  c_len: float, c_wid: float, dt_cmd: float) -> Observations:
    """The SUT's view of one run (N = 1, K = 1), as scengen's simulator builds it."""
    dx = cut.x - ego_x
    dy = cut.y - ego_y
    half_lane = 0.5 * batch.lane_width
    lane = 0 if abs(dy) <= half_lane else (1 if dy > 0 else -1)

    def one(value: float) -> NDArray[np.float64]:
        return np.array([[value]])

    return Observations(
        np.array([t]), np.array([v]), np.array([a]), batch.ego_length, batch.ego_width,
        batch.lane_width,
        np.array([[active and dx * dx + dy * dy <= sensor_range * sensor_range]]),
        one(dx), one(dx - 0.5 * batch.ego_length - 0.5 * c_len), one(dy), one(cut.v),
        one(cut.v * math.cos(cut.h)), one(cut.v * math.sin(cut.h)), one(cut.a), one(cut.h),
        one(c_len), one(c_wid), np.array([[lane]], dtype=np.int8), one(dy0), dt_cmd)


def esmini_world(batch: CutInBatch, profiles: Mapping[str, NDArray[np.float64]]
                 ) -> CutInBatch:
    """The cut-ins as esmini played them, for scengen's simulator: a :class:`CutInBatch`
    on the adapter's step (``profiles["t"]``) whose cutters are the states esmini reported
    (``simulate_esmini(..., profiles=True)``), continued at constant velocity after a
    run's end; the ego's start, sizes, ``t_p`` and ``t_end`` those of ``batch``.

    scengen's simulator on this batch, with the same SUT and settings, reproduces
    :func:`simulate_esmini`'s runs up to rounding (tested): what differs between
    ``simulate(batch)`` and ``simulate_esmini`` is then the cutter's motion as esmini
    plays the exported trajectory (its speed and heading constant along each polyline
    segment of the 0.1 s samples, where scengen interpolates them linearly)."""
    t = np.asarray(profiles["t"], dtype=np.float64)
    h = float(t[1] - t[0])
    arrays = {k: np.array(profiles[k], dtype=np.float64) for k in ("cx", "cy", "cpsi", "cv",
                                                                   "ca")}
    for i in range(batch.n):
        ok = np.flatnonzero(~np.isnan(arrays["cx"][i]))
        last = int(ok[-1])
        tau = (np.arange(t.shape[0]) - last)[last + 1:] * h
        p, v = arrays["cpsi"][i, last], arrays["cv"][i, last]
        arrays["cx"][i, last + 1:] = arrays["cx"][i, last] + v * math.cos(p) * tau
        arrays["cy"][i, last + 1:] = arrays["cy"][i, last] + v * math.sin(p) * tau
        arrays["cpsi"][i, last + 1:] = p
        arrays["cv"][i, last + 1:] = v
        arrays["ca"][i, last + 1:] = 0.0
    return CutInBatch(t=np.round(np.arange(t.shape[0]) * h, 12), lane_width=batch.lane_width,
                      ego_v0=batch.ego_v0, ego_length=batch.ego_length,
                      ego_width=batch.ego_width, c_length=batch.c_length,
                      c_width=batch.c_width, t_p=batch.t_p, t_cross=batch.t_cross,
                      t_end=batch.t_end, **arrays)


def adapter_document(xosc: bytes) -> bytes:
    """The test-mode document as the adapter runs it: its ``StopTrigger`` keeps the
    collision groups and the time limit (groups of ``SimulationTimeCondition`` only) and
    loses the "conflict over" groups: the adapter ends a run with scengen's resolution
    rule on esmini's states instead (the export's rule, "the ego not faster", stops an
    ego that fell behind and accelerates back before it closes in again)."""
    doc = etree.fromstring(xosc)
    for group in doc.xpath("/OpenSCENARIO/Storyboard/StopTrigger/ConditionGroup"):
        conds = group.findall("Condition")
        collision = bool(group.xpath(".//CollisionCondition"))
        timer = all(c.find("ByValueCondition/SimulationTimeCondition") is not None
                    for c in conds)
        if not (collision or timer):
            group.getparent().remove(group)
    out: bytes = etree.tostring(doc, xml_declaration=True, encoding="UTF-8")
    return out


def _export(scenarios: Sequence[ConcreteScenario], folder: Path) -> list[Path]:
    """The test-mode export of the scenarios in ``folder`` and the adapter's files."""
    manifest = build_manifest(seed=0, model_hash=None, sampler_settings={},
                              constraints=[], p_region=None)
    zpath = export_catalogue("xosc", ((s, {}) for s in scenarios), manifest,
                             folder / "catalogue.zip", mode="test")
    with zipfile.ZipFile(zpath) as zf:
        zf.extractall(folder)
    files = []
    for i in range(len(scenarios)):
        exported = folder / f"scenario_{i:07d}.xosc"
        path = folder / f"adapter_{i:07d}.xosc"
        path.write_bytes(adapter_document(exported.read_bytes()))
        files.append(path)
    return files


def simulate_esmini(sut: SystemUnderTest, scenarios: Sequence[ConcreteScenario], *,
                    seeds: ArrayLike | int, settings: SimSettings | None = None,
                    library: str | os.PathLike[str] | None = None,
                    profiles: bool = False, must_avoid_variant: str = "6",
                    workdir: str | os.PathLike[str] | None = None) -> EsminiResult:
    """Drive the ego of every cut-in of ``scenarios`` with ``sut`` inside esmini (module
    docstring).

    Parameters
    ----------
    sut : SystemUnderTest
        Reset once per run with that run's seed (``reset(1, seeds[i:i + 1])``).
    scenarios : sequence of ConcreteScenario
        Cut-ins as :meth:`riskcore.sut.CutInBatch.from_scenarios` accepts them (the same
        step, ego size and lane width; the ego straight at constant speed). The cutter is
        the object ``"cutter"``, else the first (as there); other objects are played by
        esmini but neither observed nor checked for contact (K = 1, as the simulator).
    seeds : int or array of shape (N,)
        As :func:`riskcore.sut.simulate` (an int gives the same per-run seeds).
    settings : SimSettings, optional
        esmini is stepped with ``dt``; the SUT asked every ``update_period`` with objects
        as of ``perception_delay`` before; ``sensor_range``, the ego's limits, ``t_max``
        and ``brake_threshold`` as in scengen's simulator.
    library : path, optional
        esmini's shared library (default: ``$SCENGEN_ESMINI_LIB``; :func:`find_library`).
    profiles : bool
        Keep the states at every step (``runs.profiles``: ``t`` (K,) and (N, K) arrays
        ``x``, ``v``, ``a`` of the ego as ``simulate``'s, its x from esmini; the cutter's
        ``cx``, ``cy``, ``cpsi``, ``cv``, ``ca`` as esmini has them, in the frame of
        the ego's start; NaN after a run's end).
    workdir : path, optional
        Where the exported files go (kept); default a temporary directory (removed).
    """
    s = settings or SimSettings()
    if not isinstance(s, SimSettings):
        raise EsminiError(f"settings: expected SimSettings, got {type(s).__name__}",
                          field="settings")
    scenarios = list(scenarios)
    if not scenarios:
        raise EsminiError("scenarios: expected at least one", field="scenarios")
    path = find_library(library)
    batch = CutInBatch.from_scenarios(scenarios)
    seed_arr = _seeds(seeds, batch.n)
    if workdir is None:
        with tempfile.TemporaryDirectory(prefix="scengen-esmini-") as tmp:
            return _simulate(sut, scenarios, batch, seed_arr, s, path, profiles,
                             must_avoid_variant, Path(tmp))
    folder = Path(workdir)
    folder.mkdir(parents=True, exist_ok=True)
    return _simulate(sut, scenarios, batch, seed_arr, s, path, profiles, must_avoid_variant,
                     folder)


def _simulate(sut: SystemUnderTest, scenarios: list[ConcreteScenario], batch: CutInBatch,
              seeds: NDArray[np.uint64], s: SimSettings, path: Path, profiles: bool,
              variant: str, folder: Path) -> EsminiResult:
    files = _export(scenarios, folder)
    runs: list[_Run] = []
    drift = np.zeros(batch.n)
    disagree = np.zeros(batch.n, dtype=np.int64)
    steps = np.zeros(batch.n, dtype=np.int64)
    prof: list[NDArray[np.float64]] = []
    with _LOCK:
        lib = EsminiLibrary.load(path)
        for i, xosc in enumerate(files):
            sc = scenarios[i]
            cutter = next((o.id for o in sc.objects if o.id == "cutter"), sc.objects[0].id)
            run, d, bad, k, p = _one(lib, xosc, (sc.ego.id, cutter), sut, batch, i,
                                     seeds[i:i + 1], s, profiles)
            runs.append(run)
            drift[i], disagree[i], steps[i] = d, bad, k
            prof.append(p)
    n = batch.n

    def col(name: str) -> NDArray[np.float64]:
        return np.array([getattr(r, name) for r in runs], dtype=np.float64)

    collided = np.array([r.collided for r in runs], dtype=np.bool_)
    m_av = must_avoid(col("intr_ttc"), col("intr_vrel"), variant)
    nan = np.full(n, np.nan)
    prof_out = None
    if profiles:
        width = max(p.shape[1] for p in prof)
        arr = np.full((len(PROFILE_KEYS), n, width), np.nan)
        for i, p in enumerate(prof):
            arr[:, i, :p.shape[1]] = p
        tk = np.arange(width) * s.dt
        after = tk[None, :] > col("end_time")[:, None] + 1e-12
        arr[:3, after] = np.nan  # the ego's, as simulate's; the cutter's up to the step
        arr[3:, np.roll(after, 1, axis=1) & after] = np.nan  # that holds the end
        prof_out = {"t": tk, **{key: arr[j] for j, key in enumerate(PROFILE_KEYS)}}
    out = RunBatch(
        collided=collided, impact_speed=col("impact"), t_contact=col("t_contact"),
        min_ttc=col("min_ttc"), min_thw=col("min_thw"), min_gap=col("min_gap"),
        max_decel=col("max_decel"), max_jerk=col("max_jerk"),
        t_brake_rel_tp=col("t_brake") - batch.t_p, r_dep_peak=nan.copy(),
        r_ind_peak=nan.copy(), r_dep_time_above=nan.copy(), must_avoid=m_av,
        violation=m_av & collided, ttc_intrusion=col("intr_ttc"),
        v_rel_intrusion=col("intr_vrel"), end_time=col("end_time"),
        end=np.array([r.end for r in runs]),
        sut=str(getattr(sut, "name", type(sut).__name__)), profiles=prof_out)
    return EsminiResult(out, EsminiDiagnostics(drift, disagree, steps))


def _one(lib: EsminiLibrary, xosc: Path, names: tuple[str, str], sut: SystemUnderTest,
         batch: CutInBatch, i: int, seed: NDArray[np.uint64], s: SimSettings, profiles: bool
         ) -> tuple[_Run, float, int, int, NDArray[np.float64]]:
    """Run i in esmini (module docstring); returns its record, the ego's largest drift
    from the vehicle model, the flag/box disagreements, the steps and the profile."""
    dt = s.dt
    jerk = s.jerk_max
    upd = s.update_steps
    delay = s.delay_steps
    n_steps = math.ceil(s.t_max / dt - 1e-9)
    ehl, ehw = 0.5 * batch.ego_length, 0.5 * batch.ego_width
    c_len, c_wid = float(batch.c_length[i]), float(batch.c_width[i])
    chl, chw = 0.5 * c_len, 0.5 * c_wid
    t_p = float(batch.t_p[i])
    assert batch.t_end is not None
    t_end = float(batch.t_end[i])
    intrude_at = 0.5 * batch.lane_width - INTRUSION_DEPTH
    name = str(getattr(sut, "name", "sut"))
    run = _Run()
    ego_id, cut_id = lib.open(xosc, *names)
    try:
        sut.reset(1, seed)
        e0 = lib.state(ego_id)
        cut = lib.state(cut_id, with_acc=True)
        x0, ey = e0.x, e0.y
        x, v, a = e0.x, float(batch.ego_v0[i]), 0.0  # the vehicle model (world frame)
        dy0 = cut.y - ey
        hist: list[tuple[float, VehicleState]] = [(e0.x, cut)]
        keep: list[tuple[float, ...]] = []
        if profiles:
            keep.append((0.0, v, a, *_rel(cut, x0, ey)))
        drift = 0.0
        bad = 0
        u = u_old = 0.0
        onset = 0.0
        # at time 0: the regulation's moment and a contact already there
        run.intrusion(0.0, 0.0, cut, e0.x, ey, v, ehl, chl, chw, intrude_at)
        k = 0
        if boxes_touch(cut, e0.x, ey, ehl, ehw, chl, chw):
            run.collided = True
            run.t_contact = 0.0
            run.impact = math.hypot(v - cut.v * math.cos(cut.h), cut.v * math.sin(cut.h))
            run.min_gap = 0.0
            run.end_time = 0.0
            run.end = "contact"
            n_steps = 0
        ego_x = e0.x
        for k in range(n_steps):
            t0 = k * dt
            if k % upd == 0:
                kd = max(k - delay, 0)
                ox, oc = hist[kd]
                obs = _observations(t0, v, a, batch, oc, ox, ey, dy0, True, s.sensor_range,
                                    c_len, c_wid, upd * dt)
                cmd = np.asarray(sut.act(obs), dtype=np.float64)
                if cmd.shape != (1,) or not math.isfinite(float(cmd[0])):
                    raise EsminiError(f"sut: {name}.act returned {cmd!r}, expected one "
                                      "finite command", field="sut")
                u_old = u
                u = min(max(float(cmd[0]), -s.a_brake_max), s.a_accel_max)
                when = getattr(sut, "command_onset", None)
                if when is None:
                    onset = 0.0
                else:
                    w = float(np.asarray(when, dtype=np.float64).reshape(-1)[0])
                    onset = 0.0 if math.isnan(w) else min(max(w - t0, 0.0), dt)
            elif k % upd == 1:
                u_old = u
                onset = 0.0
            if math.isnan(run.t_brake):
                if u_old <= -s.brake_threshold:
                    run.t_brake = t0
                elif u <= -s.brake_threshold:
                    run.t_brake = t0 + onset
            x1, v1, a1, stopped = ego_advance_with_onset(x, v, a, u_old, u, onset, jerk, dt)
            lib.report_speed(ego_id, (x1 - x) / dt)
            if not lib.step(dt):
                run.end = "esmini_stop"
                run.end_time = t0
                break
            t1 = (k + 1) * dt
            e = lib.state(ego_id)
            prev_cut = cut
            cut = lib.state(cut_id, with_acc=True)
            ego_x, ey = e.x, e.y
            drift = max(drift, abs(ego_x - x1))
            flag = lib.collides(ego_id, cut_id)
            touch = boxes_touch(cut, ego_x, ey, ehl, ehw, chl, chw)
            bad += int(flag != touch)
            if flag:
                # contact: its moment inside the step, on the interpolated states
                lo, hi = 0.0, dt
                xs = ego_x - x1  # esmini's ego against the model's (drift)
                for _ in range(_BISECT):
                    mid = 0.5 * (lo + hi)
                    xm = ego_advance_with_onset(x, v, a, u_old, u, onset, jerk, mid)[0] + xs
                    if boxes_touch(_lerp_state(prev_cut, cut, mid / dt), xm, ey, ehl, ehw,
                                   chl, chw):
                        hi = mid
                    else:
                        lo = mid
                if not touch:
                    hi = dt
                _, vc, ac, _ = ego_advance_with_onset(x, v, a, u_old, u, onset, jerk, hi)
                q = _lerp_state(prev_cut, cut, hi / dt)
                run.collided = True
                run.t_contact = t0 + hi
                run.impact = math.hypot(vc - q.v * math.cos(q.h), q.v * math.sin(q.h))
                run.min_gap = 0.0
                run.max_decel = max(run.max_decel, -ac)
                run.end_time = t0 + hi
                run.end = "contact"
                x, v, a = x1, vc, ac
                if profiles:
                    keep.append((ego_x - x0, vc, ac, *_rel(cut, x0, ey)))
                k += 1
                break
            if not stopped:
                run.max_jerk = max(run.max_jerk, abs(a1 - a) / dt)
            run.max_decel = max(run.max_decel, -a1)
            x, v, a = x1, v1, a1
            hist.append((ego_x, cut))
            if profiles:
                keep.append((ego_x - x0, v, a, *_rel(cut, x0, ey)))
            c, sn = math.cos(cut.h), math.sin(cut.h)
            clos = v - cut.v * c
            run.intrusion(t0, dt, cut, ego_x, ey, v, ehl, chl, chw, intrude_at)
            g = _clearance(cut, ego_x, ey, ehl, ehw, chl, chw)
            near = g is not None
            if g is not None and (math.isnan(t_p) or t1 >= t_p):
                run.min_gap = min(run.min_gap, g)
                if clos > 0.0:
                    run.min_ttc = min(run.min_ttc, g / clos)
                if v > 0.0:
                    run.min_thw = min(run.min_thw, g / v)
            end = ""
            if t1 >= t_end - 1e-9:
                straight = abs(sn) < STRAIGHT_SIN
                meets, _, _ = band_range(cut.x - ego_x, cut.y - ey, cut.h, chl, chw, ehw)
                behind = cut.x + chl < ego_x - ehl
                if behind and cut.v * c <= v:
                    end = "left_behind"
                elif not near and straight and not behind and not meets:
                    end = "no_conflict"
                elif near and straight and clos <= 0.0 and a <= SETTLE_ACCEL:
                    end = "settled"
            if not end and t1 >= s.t_max - 1e-9:
                end = "t_max"
            if end:
                run.end = end
                run.end_time = t1
                k += 1
                break
        prof = (np.array(keep, dtype=np.float64).T if profiles
                else np.empty((len(PROFILE_KEYS), 0), dtype=np.float64))
        return run, drift, bad, k, prof
    finally:
        lib.close()
