"""The scripted world of N cut-in runs (:class:`CutInBatch`) and what a SUT perceives of it
(:class:`Observations`, batched; :class:`Observation`, one run)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from riskcore.criticality import crossing_time, perception_time
from riskcore.scenario import ConcreteScenario, Track
from riskcore.sut.errors import SutError

__all__ = ["CutInBatch", "Observation", "Observations"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _cutter(scenario: ConcreteScenario) -> Track:
    if not scenario.objects:
        raise SutError("objects: a cut-in needs a cutter, the scenario has none")
    for o in scenario.objects:
        if o.id == "cutter":
            return o
    return scenario.objects[0]


@dataclass(frozen=True, eq=False)
class CutInBatch:
    """N cut-ins on one time grid: the cutter's scripted motion and the ego's start.

    The ego starts at x = 0, y = 0 (the centre of its lane), heading 0, speed ``ego_v0``
    and drives along +x; the simulator moves it. The cutter follows ``cx, cy, cpsi, cv,
    ca`` (road frame, centre, linear interpolation between the grid's steps) and, after
    the grid's end, holds its last speed and heading (straight, constant speed).

    Attributes
    ----------
    t : ndarray of shape (T,)
        Scenario time in s, ``t[0] = 0``, uniform step.
    lane_width : float
        m; the ego lane is ``|y| <= lane_width / 2``.
    ego_v0 : ndarray of shape (N,)
        The ego's initial speed, m/s.
    ego_length, ego_width : float
        m.
    cx, cy, cpsi, cv, ca : ndarray of shape (N, T)
        The cutter's centre (m), heading (rad, unwrapped), speed (m/s), longitudinal
        acceleration (m/s²).
    c_length, c_width : ndarray of shape (N,)
        The cutter's size, m.
    t_p : ndarray of shape (N,)
        Perception moment (UN R157: the cutter's centre has moved 0.375 m towards the ego
        lane), scenario time in s; NaN when it never does.
    t_cross : ndarray of shape (N,)
        The cutter's centre crosses into the ego lane, s (NaN: never).
    t_end : ndarray of shape (N,) or None
        From this time on the cutter drives straight at constant speed (its script is
        over); None: the grid's last time for every run. The simulator's conflict
        resolution waits for it.
    c_yaw_rate : ndarray of shape (N, T) or None
        The cutter's yaw rate, rad/s (Wagner's omega0 for ``simulate(risk=True)``); None:
        the gradient of ``cpsi``.
    """

    t: FloatArray
    lane_width: float
    ego_v0: FloatArray
    ego_length: float
    ego_width: float
    cx: FloatArray
    cy: FloatArray
    cpsi: FloatArray
    cv: FloatArray
    ca: FloatArray
    c_length: FloatArray
    c_width: FloatArray
    t_p: FloatArray
    t_cross: FloatArray
    t_end: FloatArray | None = field(default=None)
    c_yaw_rate: FloatArray | None = field(default=None)

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(self.t, dtype=np.float64)
        if t.ndim != 1 or t.shape[0] < 2:
            raise SutError("t: expected shape (T,) with T >= 2")
        if t[0] != 0.0:
            raise SutError(f"t: must start at 0 s, got {t[0]}")
        h = t[1] - t[0]
        if not (h > 0) or np.max(np.abs(np.diff(t) - h)) > 1e-9 * max(1.0, float(t[-1])):
            raise SutError("t: must be a uniform, increasing grid")
        object.__setattr__(self, "t", t)
        v0 = np.ascontiguousarray(self.ego_v0, dtype=np.float64)
        if v0.ndim != 1:
            raise SutError("ego_v0: expected shape (N,)")
        n = v0.shape[0]
        if not np.all(np.isfinite(v0)) or np.any(v0 < 0):
            raise SutError("ego_v0: speeds must be finite and >= 0 m/s")
        object.__setattr__(self, "ego_v0", v0)
        for name in ("cx", "cy", "cpsi", "cv", "ca"):
            arr = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            if arr.shape != (n, t.shape[0]):
                raise SutError(f"{name}: expected shape (N, T) = ({n}, {t.shape[0]}), "
                               f"got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise SutError(f"{name}: must be finite")
            object.__setattr__(self, name, arr)
        for name in ("c_length", "c_width", "t_p", "t_cross"):
            # a writable copy: a read-only view (broadcast_to) would give the compiled
            # loops a second signature to compile
            arr = np.array(np.broadcast_to(getattr(self, name), (n,)), dtype=np.float64)
            object.__setattr__(self, name, arr)
        if np.any(~(self.c_length > 0)) or np.any(~(self.c_width > 0)):
            raise SutError("c_length, c_width: must be > 0 m")
        for name in ("lane_width", "ego_length", "ego_width"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (float(value) > 0 and math.isfinite(value)):
                raise SutError(f"{name}: must be a positive number of m, got {value!r}")
            object.__setattr__(self, name, float(value))
        t_end = (np.full(n, t[-1]) if self.t_end is None else
                 np.ascontiguousarray(np.broadcast_to(self.t_end, (n,)), dtype=np.float64))
        object.__setattr__(self, "t_end", np.minimum(t_end, t[-1]))
        if self.c_yaw_rate is not None:
            yr = np.ascontiguousarray(self.c_yaw_rate, dtype=np.float64)
            if yr.shape != (n, t.shape[0]):
                raise SutError(f"c_yaw_rate: expected shape (N, T) = ({n}, {t.shape[0]})")
            object.__setattr__(self, "c_yaw_rate", yr)

    @property
    def n(self) -> int:
        """Number of runs N."""
        return int(self.ego_v0.shape[0])

    @property
    def dt(self) -> float:
        """The grid's step, s."""
        return float(self.t[1] - self.t[0])

    def subset(self, index: NDArray[np.intp] | slice) -> CutInBatch:
        """The runs ``index`` (same grid)."""
        assert self.t_end is not None
        return CutInBatch(
            t=self.t, lane_width=self.lane_width, ego_v0=self.ego_v0[index],
            ego_length=self.ego_length, ego_width=self.ego_width, cx=self.cx[index],
            cy=self.cy[index], cpsi=self.cpsi[index], cv=self.cv[index], ca=self.ca[index],
            c_length=self.c_length[index], c_width=self.c_width[index],
            t_p=self.t_p[index], t_cross=self.t_cross[index], t_end=self.t_end[index],
            c_yaw_rate=None if self.c_yaw_rate is None else self.c_yaw_rate[index])

    @classmethod
    def from_scenarios(cls, scenarios: Sequence[ConcreteScenario], *,
                       lane_width: float | None = None,
                       wandering_zone: float = 0.375) -> CutInBatch:
        """The batch of concrete cut-ins (the reference for tests and for recordings).

        Every scenario must share the time step and the ego's size, and its ego must drive
        straight along +x at constant speed (a generated cut-in does); the road frame is
        shifted so that the ego starts at x = 0, y = 0 and time at 0. The cutter is the
        object ``"cutter"`` (else the first). Shorter scenarios are continued at constant
        velocity to the longest's grid; ``t_end`` is the first sample from which the
        cutter's heading, speed and acceleration no longer change (its script is over). ``t_p`` and
        ``t_cross`` are those of :mod:`riskcore.criticality` (``t_cross`` from the
        provenance of a generated scenario). ``lane_width``: default the first scenario's
        provenance ``lane_width``, else 3.75 m.
        """
        if not scenarios:
            raise SutError("scenarios: expected at least one")
        first = scenarios[0]
        h = float(first.t[1] - first.t[0])
        lw = float(lane_width if lane_width is not None
                   else first.provenance.get("lane_width", 3.75))
        T = max(round((float(s.t[-1]) - float(s.t[0])) / h) + 1 for s in scenarios)
        n = len(scenarios)
        t = np.round(np.arange(T) * h, 12)
        arrays = {k: np.empty((n, T)) for k in ("cx", "cy", "cpsi", "cv", "ca", "c_yaw_rate")}
        v0 = np.empty(n)
        cl = np.empty(n)
        cw = np.empty(n)
        t_p = np.empty(n)
        t_cross = np.empty(n)
        t_end = np.empty(n)
        for i, sc in enumerate(scenarios):
            ts = np.asarray(sc.t, dtype=np.float64)
            if ts.shape[0] < 2 or abs(ts[1] - ts[0] - h) > 1e-9:
                raise SutError(f"scenarios[{i}].t: every scenario needs the step {h} s")
            e = sc.ego
            if (abs(e.length - first.ego.length) > 1e-12
                    or abs(e.width - first.ego.width) > 1e-12):
                raise SutError(f"scenarios[{i}].ego: every ego needs the same size")
            if (np.max(np.abs(e.psi)) > 1e-9 or np.ptp(e.y) > 1e-9
                    or np.ptp(e.v) > 1e-9):
                raise SutError(f"scenarios[{i}].ego: must drive straight along +x at "
                               "constant speed")
            c = _cutter(sc)
            m = ts.shape[0]
            tau = t[m:] - (ts[-1] - ts[0])  # past the end: constant velocity
            psi = np.unwrap(c.psi)
            x0, y0 = float(e.x[0]), float(e.y[0])
            arrays["cx"][i, :m] = c.x - x0
            arrays["cy"][i, :m] = c.y - y0
            arrays["cpsi"][i, :m] = psi
            arrays["cv"][i, :m] = c.v
            acc = c.a if c.a is not None else np.gradient(c.v, ts)
            arrays["ca"][i, :m] = acc
            arrays["cx"][i, m:] = c.x[-1] - x0 + c.v[-1] * math.cos(psi[-1]) * tau
            arrays["cy"][i, m:] = c.y[-1] - y0 + c.v[-1] * math.sin(psi[-1]) * tau
            arrays["cpsi"][i, m:] = psi[-1]
            arrays["cv"][i, m:] = c.v[-1]
            arrays["ca"][i, m:] = 0.0
            arrays["c_yaw_rate"][i, :m] = (c.yaw_rate if c.yaw_rate is not None
                                           else np.gradient(psi, ts))
            arrays["c_yaw_rate"][i, m:] = 0.0
            v0[i] = float(e.v[0])
            cl[i] = c.length
            cw[i] = c.width
            tp = perception_time(sc, c, wandering_zone)
            t_p[i] = math.nan if tp is None else tp - float(ts[0])
            prov = sc.provenance.get("t_cross")
            if isinstance(prov, int | float) and not isinstance(prov, bool) and sc.params:
                tc: float | None = float(prov)
            else:
                tc = crossing_time(sc, c, lw)
            t_cross[i] = math.nan if tc is None else tc - float(ts[0])
            # the script is over once heading, speed and acceleration stay constant
            dev = ((np.abs(psi - psi[-1]) > 1e-9) | (np.abs(c.v - c.v[-1]) > 1e-9)
                   | (np.abs(acc) > 1e-9))
            last = int(np.flatnonzero(dev)[-1]) + 1 if dev.any() else 0
            t_end[i] = float(ts[min(last, m - 1)] - ts[0])
        return cls(t=t, lane_width=lw, ego_v0=v0, ego_length=float(first.ego.length),
                   ego_width=float(first.ego.width), c_length=cl, c_width=cw, t_p=t_p,
                   t_cross=t_cross, t_end=t_end, **arrays)


class Observations(NamedTuple):
    """What the SUT perceives at one step, for N runs and K objects (K = 1 for a cut-in).

    Ego (proprioception, never delayed): ``t`` (N,) scenario time, s; ``ego_v`` (N,) m/s;
    ``ego_a`` (N,) the ego's actual acceleration, m/s²; ``ego_length``, ``ego_width``,
    ``lane_width`` (float, m). The ego drives at y = 0, heading 0.

    Objects (N, K), as of ``t - perception_delay`` (SimSettings): ``present`` (inside the
    sensor range, centre to centre, and the run still going; the other fields of an
    absent object are those of the world all the same, so do not use them);
    ``dx`` centre-to-centre longitudinal distance (m, + ahead); ``gap`` bumper-to-bumper
    longitudinal distance ``dx - (L_obj + L_ego) / 2`` (< 0: beside or overlapping);
    ``dy`` lateral (m, + left); ``v`` speed (m/s); ``vx``, ``vy`` velocity in the road
    frame (m/s); ``a`` longitudinal acceleration (m/s²); ``psi`` heading (rad);
    ``length``, ``width`` (m); ``lane`` (int8: 0 ego lane, +1 left, -1 right, by the
    object's centre); ``dy0`` the object's lateral offset at the first step (m; the
    reference for UN R157's perception of a lateral movement). ``dt``: the command
    returned now holds for this long, s (the update period).
    """

    t: FloatArray
    ego_v: FloatArray
    ego_a: FloatArray
    ego_length: float
    ego_width: float
    lane_width: float
    present: BoolArray
    dx: FloatArray
    gap: FloatArray
    dy: FloatArray
    v: FloatArray
    vx: FloatArray
    vy: FloatArray
    a: FloatArray
    psi: FloatArray
    length: FloatArray
    width: FloatArray
    lane: NDArray[np.int8]
    dy0: FloatArray
    dt: float = 0.0

    def run(self, i: int) -> Observation:
        """The observation of run i (scalars and (K,) arrays)."""
        return Observation(
            float(self.t[i]), float(self.ego_v[i]), float(self.ego_a[i]), self.ego_length,
            self.ego_width, self.lane_width, self.present[i], self.dx[i], self.gap[i],
            self.dy[i], self.v[i], self.vx[i], self.vy[i], self.a[i], self.psi[i],
            self.length[i], self.width[i], self.lane[i], self.dy0[i], self.dt)


class Observation(NamedTuple):
    """One run's :class:`Observations`: the ego's fields as floats, the objects' as (K,)."""

    t: float
    ego_v: float
    ego_a: float
    ego_length: float
    ego_width: float
    lane_width: float
    present: BoolArray
    dx: FloatArray
    gap: FloatArray
    dy: FloatArray
    v: FloatArray
    vx: FloatArray
    vy: FloatArray
    a: FloatArray
    psi: FloatArray
    length: FloatArray
    width: FloatArray
    lane: NDArray[np.int8]
    dy0: FloatArray
    dt: float = 0.0
