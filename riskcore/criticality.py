"""Criticality of a cut-in: margins at the perception moment, reacting reference drivers.

One :class:`Criticality` record per concrete scenario (docs/criticality.md explains the
semantics for test engineers; CONTRACT: the flat field names of ``CRITICALITY_FIELDS``).

The cutter is the object with id ``"cutter"`` (else the first object); it follows its own
recorded or generated motion and does not react. The ego reacts longitudinally only,
along its own path (the kernels in :mod:`riskcore._criticality_kernels` work in the ego's
frame; for a generated cut-in that is the road frame).

Perception moment ``t_p`` (UN R157 Annex 4 Appendix 3, cut-in: the lateral movement of
the cutting-in vehicle beyond the lateral wandering distance of 0.375 m): the first time
the cutter's *centre* has moved ``wandering_zone`` towards the ego, in the road's lateral
coordinate y, from its lateral position at the first sample of the scenario (a generated
cut-in starts at the centre of the adjacent lane, where it drives until its lateral
motion starts); linear interpolation between samples. The side "towards the ego" is the
sign of ``y_ego - y_cutter`` at the first sample. For a body that has not yawed yet every
point of its near edge moves as its centre does.

Reference drivers (all from the same scripted motion until they brake):

* ``none``: the scripted ego (constant speed for a generated cut-in);
* ``r157_cc``: perceives the cut-in at ``t_p``; it starts its reaction at the first
  moment >= ``t_p`` at which a conflict is developing: the cutter is ahead and the
  centre-line longitudinal gap is closing (or already closed). ``critical_ttc`` (default
  +inf: any closing gap) can narrow this to TTC < ``critical_ttc`` (2 s: the JRC-FSM
  implementation's gate). It brakes ``reaction_time`` later with jerk ``jerk`` up to
  ``decel_max`` and keeps braking to standstill;
* ``rss``: Shalev-Shwartz et al. (2017) longitudinal response: when the longitudinal and
  the lateral RSS distances are both violated, it brakes after the response time ``rho``
  with the same jerk-limited braking.

``a_req`` is the constant deceleration that avoids contact when braking starts at
``t_p + reaction_time`` (0 without collision at constant speed, +inf when contact comes
before), ``btn = a_req / decel_max``. ``ttr_true`` is riskcore's TTR scan (max of TTS, TTB,
TTK) at ``t_p`` with the cutter's actual future as the only predicted trajectory.
Wagner's r_dep/r_ind come from riskcore's scene engine.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from riskcore import _criticality_kernels as _ck
from riskcore import _kernels
from riskcore.errors import RiskcoreError, SettingsError
from riskcore.evasion import MANOEUVRES, evasion_label
from riskcore.scenario import ConcreteScenario, Track
from riskcore.scenario_risk import object_inputs
from riskcore.scene import EgoFuture, ObjectState, SceneResult, _Engine, default_surfaces
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces

__all__ = [
    "CLASSES",
    "CRITICALITY_FIELDS",
    "Criticality",
    "CriticalityError",
    "CriticalitySettings",
    "FieldSpec",
    "G",
    "conflict_resolution",
    "criticality_profiles",
    "evaluate_criticality",
]

FloatArray = NDArray[np.float64]

#: standard gravity in m/s² (R157 gives the careful driver's deceleration in g)
G = 9.81

#: the classes, from harmless to hopeless
CLASSES: tuple[str, ...] = ("no_conflict", "preventable", "unpreventable", "unavoidable")


class CriticalityError(RiskcoreError):
    """A scenario cannot be given a criticality record (the message says why)."""


#: settings for which +inf is a meaning, not an error
_MAY_BE_INF = frozenset({"critical_ttc"})


@dataclass(frozen=True)
class CriticalitySettings:
    """Parameters of the criticality record. Frozen; validated on construction.

    UN R157 Annex 4 Appendix 3 careful and competent (C&C) driver (figures also in
    Mattas et al. 2022, Accident Analysis & Prevention 174, 106743):

    wandering_zone : float
        Lateral wandering distance in m (0.375); moving beyond it makes a cut-in
        perceivable.
    reaction_time : float
        From perception to the start of braking, s (0.75).
    jerk : float
        Brake build-up, m/s³ (12.65: 0.774 g in 0.6 s).
    decel_max : float
        Full deceleration, m/s² (0.774 g = 7.593).
    critical_ttc : float
        The C&C driver reacts only to a developing conflict: the cutter ahead and the
        gap closing with TTC below this, s. Default +inf: any closing gap (UN R157's
        cut-in case is a cutter slower than the ALKS vehicle, para. 5.2.5.2 (a));
        2.0 is the gate of the JRC-FSM implementation (docs/criticality.md). The only
        setting that may be +inf.

    RSS (Shalev-Shwartz, Shammah, Shashua 2017, "On a formal model of safe and scalable
    self-driving cars"; parameter values as in the comparison of Mattas et al. 2022):

    rss_response_time : float
        rho, s (0.75).
    rss_accel_max : float
        Worst-case acceleration of the ego during rho, m/s² (3.0).
    rss_brake_min : float
        Braking the ego guarantees, m/s² (6.0; used in the safe distance only: the
        simulated response brakes like the C&C driver, jerk ``jerk`` up to ``decel_max``).
    rss_brake_max : float
        Hardest braking of the vehicle ahead, m/s² (6.0).
    rss_lat_margin : float
        mu, lateral fluctuation margin, m (0.3).
    rss_lat_accel_max : float
        Lateral acceleration of the cutter during rho and its lateral braking, m/s² (1.0).

    Numerics:

    step : float
        Time step of the closed-loop simulations, s (0.01); contact times are refined by
        a bracketing root search between steps.
    tail : float
        The simulations continue past the scenario's end (both vehicles at constant
        velocity) for this long, s (10), plus the time to close the gap if it is closing,
        at most ``follow_horizon``.
    follow_horizon : float
        A gap that would close more than this long after the scenario's end is taken as
        no conflict, s (60): e.g. 6 m closing at 4 mm/s.
    ttr_tail : float
        The TTR scan's horizon runs this long past the constant-speed collision, s (1.0).
    alarm_level : float
        r_dep level of ``alarm_time`` (0.5).
    """

    wandering_zone: float = 0.375
    reaction_time: float = 0.75
    jerk: float = 12.65
    decel_max: float = 0.774 * G
    critical_ttc: float = math.inf
    rss_response_time: float = 0.75
    rss_accel_max: float = 3.0
    rss_brake_min: float = 6.0
    rss_brake_max: float = 6.0
    rss_lat_margin: float = 0.3
    rss_lat_accel_max: float = 1.0
    step: float = 0.01
    tail: float = 10.0
    follow_horizon: float = 60.0
    ttr_tail: float = 1.0
    alarm_level: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise SettingsError(f"{f.name}: expected a number, got {value!r}")
            if f.name in _MAY_BE_INF and value == math.inf:
                object.__setattr__(self, f.name, math.inf)
                continue
            if not math.isfinite(value) or value < 0:
                what = ("a number >= 0 or inf" if f.name in _MAY_BE_INF
                        else "a finite number >= 0")
                raise SettingsError(f"{f.name}: must be {what}, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        for name in ("jerk", "decel_max", "rss_brake_min", "rss_brake_max",
                     "rss_lat_accel_max", "step", "wandering_zone"):
            if getattr(self, name) <= 0:
                raise SettingsError(f"{name}: must be > 0, got {getattr(self, name)}")
        if self.step > 0.1:
            raise SettingsError(f"step: at most 0.1 s, got {self.step}")

    def replace(self, **changes: Any) -> CriticalitySettings:
        """A copy with some fields changed (validated). Unknown names are an error."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise SettingsError(f"unknown setting(s) {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


class FieldSpec(NamedTuple):
    """One field of the record: unit ("-" dimensionless, "" text/bool), kind, meaning."""

    unit: str
    kind: str  # "float" | "bool" | "str"
    doc: str


def _driver_fields(name: str, label: str) -> dict[str, FieldSpec]:
    return {
        f"{name}_collision": FieldSpec("", "bool", f"{label}: does it hit the cutter?"),
        f"{name}_impact_speed": FieldSpec(
            "m/s", "float", f"{label}: relative speed at contact (0 without contact)"),
        f"{name}_min_gap": FieldSpec(
            "m", "float", f"{label}: smallest clearance to the cutter in its lane after "
            "t_p (0 with contact; inf: never ahead in its lane)"),
    }


#: The flat record: name -> (unit, kind, meaning). The same names everywhere.
CRITICALITY_FIELDS: dict[str, FieldSpec] = {
    "t_p": FieldSpec("s", "float", "perception moment: the cutter has moved 0.375 m "
                     "towards the ego lane (UN R157); null: never"),
    "t_cross": FieldSpec("s", "float", "the cutter's centre crosses the lane marking"),
    "ttr_true": FieldSpec("s", "float", "time to react at t_p against the cutter's actual "
                          "path, s after t_p (inf: no collision at constant speed; "
                          "0: nothing avoids it)"),
    "ttr_manoeuvre": FieldSpec("", "str", "manoeuvre(s) giving ttr_true; 'none' when "
                               "nothing works; null without collision"),
    "a_req": FieldSpec("m/s²", "float", "constant deceleration needed when braking starts "
                       "0.75 s after t_p (0: none needed; inf: contact before)"),
    "btn": FieldSpec("-", "float", "brake threat number a_req / (0.774 g); >= 1: the "
                     "careful driver cannot prevent it"),
    "class": FieldSpec("", "str", "no_conflict | preventable | unpreventable | "
                       "unavoidable"),
    **_driver_fields("none", "ego at its scripted (constant) speed"),
    **_driver_fields("r157_cc", "UN R157 careful and competent driver"),
    "r157_cc_t_brake": FieldSpec("s", "float", "R157 driver: braking starts (null: never)"),
    **_driver_fields("rss", "RSS longitudinal response"),
    "rss_t_brake": FieldSpec("s", "float", "RSS driver: braking starts (null: never)"),
    "r_dep_tp": FieldSpec("-", "float", "Wagner's risk r_dep at t_p, scripted ego"),
    "r_ind_tp": FieldSpec("-", "float", "Wagner's r_ind at t_p, scripted ego"),
    "r_dep_cross": FieldSpec("-", "float", "r_dep at the crossing, scripted ego"),
    "r_ind_cross": FieldSpec("-", "float", "r_ind at the crossing, scripted ego"),
    "r_dep_tp_r157": FieldSpec("-", "float", "r_dep at t_p, ego = R157 driver"),
    "r_ind_tp_r157": FieldSpec("-", "float", "r_ind at t_p, ego = R157 driver"),
    "r_dep_cross_r157": FieldSpec("-", "float", "r_dep at the crossing, ego = R157 driver"),
    "r_ind_cross_r157": FieldSpec("-", "float", "r_ind at the crossing, ego = R157 driver"),
    "alarm_time": FieldSpec("s", "float", "from t_p until the scripted-ego r_dep first "
                            "reaches 0.5 (null: never)"),
    "risk_peak": FieldSpec("-", "float", "maximum r_dep over the run, scripted ego"),
}


@dataclass(frozen=True)
class Criticality:
    """The criticality record of one scenario; ``to_record()`` is the flat form.

    ``values`` maps every name of :data:`CRITICALITY_FIELDS` to a float (may be +inf), a
    bool, a str or None.
    """

    values: dict[str, float | bool | str | None]

    def __post_init__(self) -> None:
        missing = [k for k in CRITICALITY_FIELDS if k not in self.values]
        extra = [k for k in self.values if k not in CRITICALITY_FIELDS]
        if missing or extra:
            raise CriticalityError(f"record fields: missing {missing}, unknown {extra}")

    def __getitem__(self, name: str) -> float | bool | str | None:
        return self.values[name]

    @property
    def category(self) -> str:
        """The class (``"class"`` is a Python keyword)."""
        return str(self.values["class"])

    def to_record(self) -> dict[str, float | bool | str | None]:
        """Flat dict in the order of CRITICALITY_FIELDS (a fresh copy)."""
        return {k: self.values[k] for k in CRITICALITY_FIELDS}


# --------------------------------------------------------------------------- frames
@dataclass(frozen=True, eq=False)
class _Frames:
    """The scenario on the simulation grid t_k = t0 + k h, in the ego's frame."""

    t0: float
    h: float
    cs: FloatArray  # cutter centre along the ego path, m
    cd: FloatArray  # cutter centre lateral to the ego path, m
    cpsi: FloatArray  # cutter heading relative to the ego's, rad
    cv: FloatArray  # cutter speed, m/s
    es: FloatArray  # scripted ego arc length, m
    ev: FloatArray  # scripted ego speed, m/s
    ex: FloatArray  # scripted ego road-frame centre and heading (for the reacted track)
    ey: FloatArray
    epsi: FloatArray
    ehl: float
    ehw: float
    chl: float
    chw: float
    t_end: float
    k_const: int  # from this grid step on: straight, constant speeds (-1: never)
    t_stop: float  # the simulated time ends here (the grid's last time)

    def times(self) -> FloatArray:
        return np.asarray(self.t0 + np.arange(self.cs.shape[0]) * self.h, dtype=np.float64)


def _cutter_index(scenario: ConcreteScenario) -> int:
    if not scenario.objects:
        raise CriticalityError("objects: a cut-in needs a cutter, the scenario has none")
    for i, o in enumerate(scenario.objects):
        if o.id == "cutter":
            return i
    return 0


def _frames(t: FloatArray, ego: Track, cutter: Track, s: CriticalitySettings) -> _Frames:
    t = np.asarray(t, dtype=np.float64)
    pe = np.unwrap(ego.psi)
    pc = np.unwrap(cutter.psi)
    ce, se = np.cos(pe), np.sin(pe)
    dx = cutter.x - ego.x
    dy = cutter.y - ego.y
    lon = dx * ce + dy * se
    lat = -dx * se + dy * ce
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(ego.x), np.diff(ego.y)))])
    s_e = ego.x[0] + arc
    cs_k = s_e + lon
    rel = pc - pe
    ehl, chl = 0.5 * ego.length, 0.5 * cutter.length
    # how long past the end: closing at the end adds the time to close the gap
    gap_end = cs_k[-1] - s_e[-1] - ehl - chl
    closing = ego.v[-1] - cutter.v[-1] * math.cos(rel[-1])
    tail = s.tail + min(gap_end / closing if closing > 0 and gap_end > 0 else 0.0,
                        s.follow_horizon)
    h = s.step
    n = math.floor((t[-1] + tail - t[0]) / h) + 1
    tg = t[0] + np.arange(n) * h
    after = tg > t[-1]
    tau = np.where(after, tg - t[-1], 0.0)

    def ext(values: FloatArray, rate: float) -> FloatArray:
        return np.where(after, values[-1] + rate * tau, np.interp(tg, t, values))

    vc_end, ve_end = float(cutter.v[-1]), float(ego.v[-1])
    # after the end the ego's heading is fixed: the cutter advances vc cos(rel) along it
    cs = ext(cs_k, vc_end * math.cos(rel[-1]))
    cd = ext(lat, vc_end * math.sin(rel[-1]))
    es = ext(s_e, ve_end)
    return _Frames(
        t0=float(t[0]), h=h, cs=np.ascontiguousarray(cs), cd=np.ascontiguousarray(cd),
        cpsi=np.ascontiguousarray(ext(rel, 0.0)), cv=np.ascontiguousarray(ext(cutter.v, 0.0)),
        es=np.ascontiguousarray(es), ev=np.ascontiguousarray(ext(ego.v, 0.0)),
        ex=ext(ego.x, ve_end * math.cos(pe[-1])), ey=ext(ego.y, ve_end * math.sin(pe[-1])),
        epsi=ext(pe, 0.0), ehl=ehl, ehw=0.5 * ego.width, chl=chl, chw=0.5 * cutter.width,
        t_end=float(t[-1]),
        k_const=int(np.searchsorted(tg, t[-1], side="right")) - 1
        if math.sin(rel[-1]) == 0.0 else -1,
        t_stop=float(tg[-1]))


def _first_reach(t: FloatArray, m: FloatArray, level: float) -> float | None:
    """First time the series m reaches level (linear interpolation), None if never."""
    idx = np.flatnonzero(m >= level)
    if idx.size == 0:
        return None
    i = int(idx[0])
    if i == 0:
        return float(t[0])
    f = (level - m[i - 1]) / (m[i] - m[i - 1])
    return float(t[i - 1] + f * (t[i] - t[i - 1]))


def perception_time(scenario: ConcreteScenario, cutter: Track,
                    wandering_zone: float = 0.375) -> float | None:
    """t_p: the cutter's centre has moved ``wandering_zone`` towards the ego (module doc)."""
    toward = math.copysign(1.0, scenario.ego.y[0] - cutter.y[0])
    move = (cutter.y - cutter.y[0]) * toward
    return _first_reach(np.asarray(scenario.t, dtype=np.float64), move, wandering_zone)


def crossing_time(scenario: ConcreteScenario, cutter: Track,
                  lane_width: float) -> float | None:
    """First time the cutter's centre is within lane_width / 2 of the ego's centre line."""
    off = np.abs(cutter.y - scenario.ego.y)
    return _first_reach(np.asarray(scenario.t, dtype=np.float64), -off, -lane_width / 2.0)


# --------------------------------------------------------------------------- drivers
class _Drivers(NamedTuple):
    none: tuple[float, float, float]  # contact time (NaN none), impact speed, min gap
    r157: tuple[float, float, float]
    r157_t_brake: float  # NaN: never
    rss: tuple[float, float, float]
    rss_t_brake: float


def _run_drivers(f: _Frames, t_p: float | None, s: CriticalitySettings) -> _Drivers:
    common = (f.t0, f.h, f.cs, f.cd, f.cpsi, f.cv, f.es, f.ev, f.ehl, f.ehw, f.chl, f.chw)
    t_from = f.t0 if t_p is None else t_p
    none = _ck.drive(*common, math.nan, s.jerk, s.decel_max, t_from, f.k_const, f.t_stop)
    if t_p is None:
        t_b = math.nan
    else:
        t_r = _ck.r157_reaction_start(f.t0, f.h, f.cs, f.cpsi, f.cv, f.es, f.ev,
                                      f.ehl + f.chl, t_p, s.critical_ttc, f.k_const,
                                      f.t_stop)
        t_b = t_r + s.reaction_time
    r157 = _ck.drive(*common, t_b, s.jerk, s.decel_max, t_from, f.k_const, f.t_stop)
    t_trig = _ck.rss_trigger(*common, s.rss_response_time, s.rss_accel_max,
                             s.rss_brake_min, s.rss_brake_max, s.rss_lat_margin,
                             s.rss_lat_accel_max)
    t_rb = t_trig + s.rss_response_time
    rss = _ck.drive(*common, t_rb, s.jerk, s.decel_max, t_from, f.k_const, f.t_stop)
    return _Drivers(none, r157, t_b, rss, t_rb)


def _braked(t_b: float, contact: float) -> float | None:
    """Braking start as reported: None when it never comes or comes after the contact."""
    if math.isnan(t_b) or (not math.isnan(contact) and contact <= t_b):
        return None
    return float(t_b)


def _ttr_true(f: _Frames, t_p: float, contact: float, rs: RiskSettings,
              s: CriticalitySettings) -> tuple[float, str | None]:
    """riskcore's TTR scan at t_p against the cutter's actual future (ego frame)."""
    dt = rs.dt
    n = math.ceil((contact - t_p) / dt - 1e-9) + math.ceil(s.ttr_tail / dt)
    n = max(1, min(n, 1000))
    tq = t_p + np.arange(n + 1) * dt
    tg = f.times()
    poses = np.zeros((n + 1, 4))
    poses[:, 0] = np.interp(tq, tg, f.es)
    poses[:, 2] = 1.0
    v = np.interp(tq, tg, f.ev)
    traj = np.empty((1, n + 1, 4))
    traj[0, :, 0] = np.interp(tq, tg, f.cs)
    traj[0, :, 1] = np.interp(tq, tg, f.cd)
    psi = np.interp(tq, tg, f.cpsi)
    traj[0, :, 2] = np.cos(psi)
    traj[0, :, 3] = np.sin(psi)
    man_a = np.empty((n, len(MANOEUVRES)))
    man_w = np.empty((n, len(MANOEUVRES)))
    for k, man in enumerate(MANOEUVRES):
        man_a[:, k], man_w[:, k] = man.inputs(v[:n], rs)
    eva = np.empty((n, len(MANOEUVRES), n + 1, 4))
    done = np.zeros((n, len(MANOEUVRES)), dtype=np.bool_)
    first, react, mask = _kernels.ttr_scan(traj, f.chl, f.chw, poses, v, f.ehl, f.ehw,
                                           man_a, man_w, dt, eva, done)
    if first[0] < 0:  # the grazing contact falls between the scan's steps
        return math.inf, None
    if react[0] < 0:
        return 0.0, "none"
    # a whole number of steps: rounded so that 14 x 0.1 s reads 1.4, not 1.4000000000000001
    return round(float(react[0] * dt), 12), evasion_label(int(mask[0]), True)


# --------------------------------------------------------------------------- Wagner
class _Wagner:
    """Scenes of the scenario at arbitrary times, with the scripted or a reacted ego.

    A one-object scenario (every cut-in) goes through one compiled call per scene
    (:func:`riskcore._criticality_kernels.scene_risk`, the engine's own kernels); more
    objects through riskcore's scene engine. Both give riskcore's r_dep and r_ind.
    """

    def __init__(self, scenario: ConcreteScenario, f: _Frames, rs: RiskSettings,
                 surfaces: InputSurfaces, s: CriticalitySettings) -> None:
        self.scenario = scenario
        self.f = f
        self.rs = rs
        self.s = s
        self.surfaces = surfaces
        self.engine = _Engine(rs, surfaces, MANOEUVRES)
        t = np.asarray(scenario.t, dtype=np.float64)
        self.t = t
        self.objects = []
        for track in scenario.objects:
            a0, w0 = object_inputs(t, track)
            self.objects.append((track, np.unwrap(track.psi), a0, w0))
        self._tg = f.times()
        self._offsets = np.arange(rs.n_steps + 1) * rs.dt
        if len(self.objects) == 1:
            track, _, a0, w0 = self.objects[0]
            mean_a, std_a = surfaces.accel(track.v, a0)
            mean_w, std_w = surfaces.turn(track.v, w0)
            self._dist = np.column_stack([mean_a, std_a, mean_w, std_w])

    def ego_track(self, tq: FloatArray, t_b: float) -> tuple[FloatArray, ...]:
        """Road-frame (x, y, psi, v) of the ego braking from t_b (NaN: scripted)."""
        f = self.f
        tq = np.ascontiguousarray(tq, dtype=np.float64)
        s_scr = np.interp(tq, self._tg, f.es)
        if math.isnan(t_b):
            return (np.interp(tq, self._tg, f.ex), np.interp(tq, self._tg, f.ey),
                    np.interp(tq, self._tg, f.epsi), np.interp(tq, self._tg, f.ev))
        s_r, v_r = _ck.ego_track(tq, f.t0, f.h, f.es, f.ev, t_b, self.s.jerk,
                                 self.s.decel_max)
        back = s_scr - s_r
        psi = np.interp(tq, self._tg, f.epsi)
        x = np.interp(tq, self._tg, f.ex) - back * np.cos(psi)
        y = np.interp(tq, self._tg, f.ey) - back * np.sin(psi)
        return x, y, psi, v_r

    def first_reaching(self, ks: Sequence[int], level: float, cache: dict[int, float],
                       first_block: int = 8) -> int | None:
        """Scripted-ego r_dep at the sample steps ``ks`` (indices into ``t``), in order and
        stored in ``cache``, until one reaches ``level``: its position in ``ks`` (None: no
        step does). Steps already in ``cache`` are not computed again. The steps go in
        blocks (``first_block``, then doubling) through one compiled call each, which stops
        at the first scene reaching ``level``; the risks are those of :meth:`scene`."""
        i, size = 0, max(1, int(first_block))
        while i < len(ks):
            block = list(ks[i:i + size])
            todo = [k for k in block if k not in cache]
            if todo:
                self._step_risks(todo, level, cache)
            for j, k in enumerate(block):
                if cache[k] >= level:
                    return i + j
            i += len(block)
            size *= 2
        return None

    def _step_risks(self, ks: list[int], level: float, cache: dict[int, float]) -> None:
        """r_dep (scripted ego) at the steps ks into cache, in order, stopping after the
        first that reaches level."""
        if len(self.objects) != 1:
            for k in ks:
                cache[k] = self.scene(float(self.t[k]))[0]
                if cache[k] >= level:
                    return
            return
        rs, f = self.rs, self.f
        track, psi_u, _, _ = self.objects[0]
        idx = np.asarray(ks, dtype=np.int64)
        tq = self.t[idx][:, None] + self._offsets[None, :]  # as scene(): t_now + offsets
        x, y, psi, v = (np.interp(tq, self._tg, arr) for arr in (f.ex, f.ey, f.epsi, f.ev))
        n = rs.n_steps
        man_a = np.empty((idx.shape[0], n, len(MANOEUVRES)))
        man_w = np.empty((idx.shape[0], n, len(MANOEUVRES)))
        for j, man in enumerate(MANOEUVRES):
            man_a[:, :, j], man_w[:, :, j] = man.inputs(v[:, :n], rs)
        out = np.full(idx.shape[0], np.nan)
        eng = self.engine
        done = _ck.scene_risks(
            track.x[idx], track.y[idx], psi_u[idx], track.v[idx], self._dist[idx], eng._za,
            eng._zw, eng._weight, 0.5 * track.length, 0.5 * track.width, x, y, psi, v,
            0.5 * self.scenario.ego.length, 0.5 * self.scenario.ego.width, man_a, man_w,
            rs.dt, rs.t_pnr, rs.t_max, rs.m, float(level), out)
        for j in range(int(done)):
            cache[ks[j]] = float(out[j])

    def scene(self, t_now: float, t_b: float = math.nan) -> tuple[float, float]:
        """(r_dep, r_ind) of the scene at t_now with the ego braking from t_b (NaN: never)."""
        rs = self.rs
        x, y, psi, v = self.ego_track(np.asarray(t_now + self._offsets, dtype=np.float64), t_b)
        t = self.t
        if len(self.objects) == 1:
            track, psi_u, a0, w0 = self.objects[0]
            k = int(np.searchsorted(t, t_now))
            if k < t.shape[0] and t[k] == t_now:
                ox, oy, op, ov = track.x[k], track.y[k], psi_u[k], track.v[k]
                ma, sa, mw, sw = self._dist[k]
            else:
                ox, oy, op, ov = (float(np.interp(t_now, t, arr)) for arr in
                                  (track.x, track.y, psi_u, track.v))
                ma, sa = self.surfaces.accel.at(ov, float(np.interp(t_now, t, a0)))
                mw, sw = self.surfaces.turn.at(ov, float(np.interp(t_now, t, w0)))
            n = rs.n_steps
            man_a = np.empty((n, len(MANOEUVRES)))
            man_w = np.empty((n, len(MANOEUVRES)))
            for j, man in enumerate(MANOEUVRES):
                man_a[:, j], man_w[:, j] = man.inputs(v[:n], rs)
            eng = self.engine
            r = float(_ck.scene_risk(
                float(ox), float(oy), float(op), float(ov), float(ma), float(sa), float(mw),
                float(sw), eng._za, eng._zw, eng._weight, 0.5 * track.length,
                0.5 * track.width, x, y, psi, np.ascontiguousarray(v),
                0.5 * self.scenario.ego.length, 0.5 * self.scenario.ego.width, man_a, man_w,
                rs.dt, rs.t_pnr, rs.t_max, rs.m))
            return r, r
        ego = EgoFuture(x=x, y=y, psi=psi, v=v, length=self.scenario.ego.length,
                        width=self.scenario.ego.width)
        arrays = self.engine.ego_arrays(ego)
        results = []
        for track, psi_u, a0, w0 in self.objects:
            state = ObjectState(
                id=track.id, x=float(np.interp(t_now, t, track.x)),
                y=float(np.interp(t_now, t, track.y)),
                psi=float(np.interp(t_now, t, psi_u)), v=float(np.interp(t_now, t, track.v)),
                a0=float(np.interp(t_now, t, a0)), omega0=float(np.interp(t_now, t, w0)),
                length=track.length, width=track.width)
            results.append(self.engine.object(ego, arrays, state))
        res: SceneResult = self.engine.consolidate(tuple(results))
        return res.r_dep, res.r_ind


def _lane_width(scenario: ConcreteScenario, lane_width: float | None) -> float:
    lw = scenario.provenance.get("lane_width", 3.75) if lane_width is None else lane_width
    if isinstance(lw, bool) or not isinstance(lw, int | float) or not (
            math.isfinite(lw) and lw > 0):
        raise CriticalityError(f"lane_width: must be a positive number of m, got {lw!r}")
    return float(lw)


def _check_not_cut_off(scenario: ConcreteScenario) -> None:
    t_res = scenario.provenance.get("t_resolved")
    if (isinstance(t_res, int | float) and not isinstance(t_res, bool)
            and float(scenario.t[-1]) < float(t_res) - 1e-9):
        raise CriticalityError(
            f"t: the scenario ends at {float(scenario.t[-1]):.3f} s, before its conflict "
            f"is resolved at {float(t_res):.3f} s; no criticality from a cut-off")


def conflict_resolution(t: FloatArray, ego: Track, cutter: Track,
                        settings: CriticalitySettings | None = None) -> tuple[float, str]:
    """When the conflict of a cut-in is over, for the scripted ego: (time in s, how).

    The motion after ``t[-1]`` is taken at constant velocity (as in the simulations), so
    ``t[-1]`` should be at or after the moment both vehicles stop changing speed and
    heading. How: ``"contact"`` (the scripted ego hits the cutter within the simulated
    time, see ``CriticalitySettings.follow_horizon``), ``"left_behind"`` (the ego is
    still faster at ``t[-1]`` but the cutter is not in the ego's lane: the time its front
    passes the ego's rear), ``"settled"`` (otherwise: ``t[-1]``).
    """
    s = settings or CriticalitySettings()
    f = _frames(t, ego, cutter, s)
    contact, _, _ = _ck.drive(f.t0, f.h, f.cs, f.cd, f.cpsi, f.cv, f.es, f.ev, f.ehl, f.ehw,
                              f.chl, f.chw, math.nan, s.jerk, s.decel_max, f.t0, f.k_const,
                              f.t_stop)
    if not math.isnan(contact):
        return float(contact), "contact"
    t_end = float(np.asarray(t)[-1])
    k = round((t_end - f.t0) / f.h)
    closing = f.ev[k] - f.cv[k] * math.cos(f.cpsi[k])
    ahead = f.cs[k] + f.chl - (f.es[k] - f.ehl)
    p = f.cpsi[k]
    in_lane, _, _ = _ck.band_range(f.cs[k], f.cd[k], math.cos(p), math.sin(p), f.chl, f.chw,
                                   f.ehw)
    if closing > 0 and ahead > 0 and not in_lane and ahead / closing <= s.follow_horizon:
        return t_end + float(ahead / closing), "left_behind"
    return t_end, "settled"


def evaluate_criticality(scenario: ConcreteScenario, *, lane_width: float | None = None,
                         settings: CriticalitySettings | None = None,
                         risk_settings: RiskSettings | None = None,
                         surfaces: InputSurfaces | None = None) -> Criticality:
    """The criticality record of one cut-in (see the module docstring and CONTRACT).

    Parameters
    ----------
    scenario : ConcreteScenario
        The ego and at least one object; the cutter is the object ``"cutter"`` (else the
        first). Wagner's risks use every object.
    lane_width : float, optional
        Lane width in m for the crossing moment (default: the scenario's provenance
        ``lane_width``, else 3.75).
    settings : CriticalitySettings, optional
    risk_settings : RiskSettings, optional
        Wagner's risk and the TTR scan's manoeuvres (riskcore's defaults when None).
    surfaces : InputSurfaces, optional
        Input distributions of Wagner's risk (the packaged default when None).

    Returns
    -------
    Criticality
    """
    if not isinstance(scenario, ConcreteScenario):
        raise CriticalityError(f"scenario: expected a ConcreteScenario, got "
                               f"{type(scenario).__name__}")
    s = settings or CriticalitySettings()
    rs = risk_settings or RiskSettings()
    lw = _lane_width(scenario, lane_width)
    _check_not_cut_off(scenario)
    for name, track in (("ego", scenario.ego),
                        *((f"objects[{i}]", o) for i, o in enumerate(scenario.objects))):
        if (track.v < 0).any():
            k = int(np.flatnonzero(track.v < 0)[0])
            raise CriticalityError(f"{name}.v[{k}]: speed must be >= 0, got {track.v[k]}")
    cutter = scenario.objects[_cutter_index(scenario)]
    f = _frames(scenario.t, scenario.ego, cutter, s)
    t_p = perception_time(scenario, cutter, s.wandering_zone)
    prov_cross = scenario.provenance.get("t_cross")
    if isinstance(prov_cross, int | float) and not isinstance(prov_cross, bool) and \
            scenario.params:
        t_cross: float | None = float(prov_cross)
    else:
        t_cross = crossing_time(scenario, cutter, lw)
    d = _run_drivers(f, t_p, s)
    c_none = d.none[0]
    none_coll = not math.isnan(c_none)
    r157_coll = not math.isnan(d.r157[0])
    rec: dict[str, float | bool | str | None] = {"t_p": t_p, "t_cross": t_cross}
    # margins at t_p
    if t_p is None:
        a_req: float | None = 0.0 if not none_coll else None
        ttr: float | None = math.inf if not none_coll else None
        man: str | None = None
    elif not none_coll:
        a_req, ttr, man = 0.0, math.inf, None
    else:
        t_b0 = t_p + s.reaction_time
        a_req = math.inf if c_none <= t_b0 else float(_ck.required_decel(
            f.t0, f.h, f.cs, f.cd, f.cpsi, f.cv, f.es, f.ev, f.ehl, f.ehw, f.chl, f.chw, t_b0,
            f.k_const))
        ttr, man = _ttr_true(f, t_p, c_none, rs, s)
    rec["ttr_true"] = ttr
    rec["ttr_manoeuvre"] = man
    rec["a_req"] = a_req
    rec["btn"] = None if a_req is None else a_req / s.decel_max
    if not none_coll:
        cls = "no_conflict"
    elif not r157_coll:
        cls = "preventable"
    elif man == "none":
        cls = "unavoidable"
    else:
        cls = "unpreventable"
    rec["class"] = cls
    for name, (contact, speed, gap) in (("none", d.none), ("r157_cc", d.r157),
                                        ("rss", d.rss)):
        rec[f"{name}_collision"] = not math.isnan(contact)
        rec[f"{name}_impact_speed"] = float(speed)
        rec[f"{name}_min_gap"] = float(gap)
    rec["r157_cc_t_brake"] = _braked(d.r157_t_brake, d.r157[0])
    rec["rss_t_brake"] = _braked(d.rss_t_brake, d.rss[0])
    rec.update(_wagner_fields(scenario, f, t_p, t_cross, d, rs, surfaces, s))
    return Criticality(values=rec)


def _wagner_fields(scenario: ConcreteScenario, f: _Frames, t_p: float | None,
                   t_cross: float | None, d: _Drivers, rs: RiskSettings,
                   surfaces: InputSurfaces | None, s: CriticalitySettings
                   ) -> dict[str, float | bool | str | None]:
    w = _Wagner(scenario, f, rs, surfaces or default_surfaces(), s)
    out: dict[str, float | bool | str | None] = {}
    t_b = d.r157_t_brake
    for label, when in (("tp", t_p), ("cross", t_cross)):
        if when is None:
            for suffix in ("", "_r157"):
                out[f"r_dep_{label}{suffix}"] = None
                out[f"r_ind_{label}{suffix}"] = None
            continue
        sc = w.scene(when)
        out[f"r_dep_{label}"], out[f"r_ind_{label}"] = sc
        sr = sc if math.isnan(t_b) else w.scene(when, t_b)
        out[f"r_dep_{label}_r157"], out[f"r_ind_{label}_r157"] = sr
    t = w.t
    cache: dict[int, float] = {}
    contact = d.none[0]
    # alarm: from t_p on (t_p itself, then the samples up to contact) until r_dep >=
    # alarm_level
    alarm: float | None = None
    if t_p is not None:
        r0 = out["r_dep_tp"]
        if isinstance(r0, float) and r0 >= s.alarm_level:
            alarm = 0.0
        else:
            ks = [int(i) for i in np.flatnonzero(t > t_p)
                  if math.isnan(contact) or t[i] <= contact]
            hit = w.first_reaching(ks, s.alarm_level, cache)
            if hit is not None:
                alarm = float(t[ks[hit]] - t_p)
    out["alarm_time"] = alarm
    # peak: r_dep <= 1, so one step at 1 ends the search; the step before contact first
    order = list(range(t.shape[0]))
    if not math.isnan(contact):
        before = int(np.searchsorted(t, contact)) - 1
        if 0 <= before < t.shape[0]:
            order.remove(before)
            order.insert(0, before)
    hit = w.first_reaching(order, 1.0, cache, first_block=1)
    peak = max([0.0, *(cache[k] for k in order[:len(order) if hit is None else hit + 1])])
    out["risk_peak"] = peak
    return out


def criticality_profiles(scenario: ConcreteScenario, *, settings: CriticalitySettings | None
                         = None, risk_settings: RiskSettings | None = None,
                         surfaces: InputSurfaces | None = None) -> dict[str, Any]:
    """Wagner's risk over the scenario for the scripted and the R157 ego (scenario view).

    Returns a dict of plain lists: ``t`` (the scenario's steps, s), ``r_dep``, ``r_ind``
    (scripted ego), ``r_dep_r157``, ``r_ind_r157`` (ego = R157 driver), ``r157_ego`` with
    ``x, y, psi, v`` of the R157 driver's track at ``t``, and the scalars ``t_p``,
    ``t_cross`` (the cutter's centre within lane_width / 2 of the ego's) and
    ``r157_t_brake`` (None: never).
    """
    s = settings or CriticalitySettings()
    rs = risk_settings or RiskSettings()
    cutter = scenario.objects[_cutter_index(scenario)]
    f = _frames(scenario.t, scenario.ego, cutter, s)
    t_p = perception_time(scenario, cutter, s.wandering_zone)
    d = _run_drivers(f, t_p, s)
    w = _Wagner(scenario, f, rs, surfaces or default_surfaces(), s)
    t = np.asarray(scenario.t, dtype=np.float64)
    t_b = d.r157_t_brake
    plain = [w.scene(float(tt)) for tt in t]
    reacted = plain if math.isnan(t_b) else [w.scene(float(tt), t_b) for tt in t]
    x, y, psi, v = w.ego_track(t, t_b)
    prov_cross = scenario.provenance.get("t_cross")
    t_cross = (float(prov_cross) if isinstance(prov_cross, int | float) and scenario.params
               else crossing_time(scenario, cutter, _lane_width(scenario, None)))
    return {
        "t": t.tolist(),
        "r_dep": [r[0] for r in plain], "r_ind": [r[1] for r in plain],
        "r_dep_r157": [r[0] for r in reacted], "r_ind_r157": [r[1] for r in reacted],
        "r157_ego": {"x": x.tolist(), "y": y.tolist(), "psi": psi.tolist(),
                     "v": v.tolist()},
        "t_p": t_p, "t_cross": t_cross, "r157_t_brake": _braked(t_b, d.r157[0]),
    }


def settings_from_dict(data: Mapping[str, Any]) -> CriticalitySettings:
    """Build settings from a mapping of field names (missing ones take the defaults)."""
    if not isinstance(data, Mapping):
        raise SettingsError("settings: expected an object")
    return CriticalitySettings().replace(**dict(data))
