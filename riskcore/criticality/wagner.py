"""Wagner's risk along a cut-in for the criticality record: the scenes at t_p and at the
crossing, the alarm time, the peak, and the profiles of the scenario view."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riskcore.criticality import kernels as _ck
from riskcore.criticality.drivers import (
    _braked,
    _cutter_index,
    _Drivers,
    _Frames,
    _frames,
    _lane_width,
    _run_drivers,
    crossing_time,
    perception_time,
)
from riskcore.criticality.record import CriticalitySettings
from riskcore.evasion import MANOEUVRES
from riskcore.scenario import ConcreteScenario
from riskcore.scenario_risk import object_inputs
from riskcore.scene import EgoFuture, ObjectState, SceneResult, _Engine, default_surfaces
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces

__all__ = ["criticality_profiles"]

FloatArray = NDArray[np.float64]


class _Wagner:
    """Scenes of the scenario at arbitrary times, with the scripted or a reacted ego.

    A one-object scenario (every cut-in) goes through one compiled call per scene
    (:func:`riskcore.criticality.kernels.scene_risk`, the engine's own kernels); more
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


def _wagner_fields(scenario: ConcreteScenario, f: _Frames, t_p: float | None,
                   t_cross: float | None, d: _Drivers, rs: RiskSettings,
                   surfaces: InputSurfaces | None, s: CriticalitySettings,
                   scan: bool = True) -> dict[str, float | bool | str | None]:
    """Wagner's risk fields of the record. ``scan=False`` keeps the scenes at t_p (scripted
    and R157 ego) and leaves out the rest (null): the scenes at the crossing and what
    needs r_dep at every step of the run (``alarm_time``, ``risk_peak``), which cost more
    than the rest of the record together (the peak is 1 for nearly every cut-in on a
    collision course: the scripted ego never reacts)."""
    w = _Wagner(scenario, f, rs, surfaces or default_surfaces(), s)
    out: dict[str, float | bool | str | None] = {}
    t_b = d.r157_t_brake
    for label, when in (("tp", t_p), ("cross", t_cross)):
        if when is None or (label == "cross" and not scan):
            for suffix in ("", "_r157"):
                out[f"r_dep_{label}{suffix}"] = None
                out[f"r_ind_{label}{suffix}"] = None
            continue
        sc = w.scene(when)
        out[f"r_dep_{label}"], out[f"r_ind_{label}"] = sc
        sr = sc if math.isnan(t_b) else w.scene(when, t_b)
        out[f"r_dep_{label}_r157"], out[f"r_ind_{label}_r157"] = sr
    if not scan:
        out["alarm_time"] = None
        out["risk_peak"] = None
        return out
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
