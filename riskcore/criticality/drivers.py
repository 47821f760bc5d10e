"""The criticality record's frames, timing and reference drivers (module docstring of
:mod:`riskcore.criticality`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from riskcore import kernels as _kernels
from riskcore.criticality import kernels as _ck
from riskcore.criticality.record import CriticalityError, CriticalitySettings
from riskcore.evasion import MANOEUVRES, evasion_label
from riskcore.scenario import ConcreteScenario, Track
from riskcore.settings import RiskSettings

__all__ = ["conflict_resolution", "crossing_time", "perception_time"]

FloatArray = NDArray[np.float64]


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
