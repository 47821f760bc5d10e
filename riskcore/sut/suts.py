"""Built-in systems under test, vectorised over the runs (docs/systems.md has the
parameters and their sources).

A *leader* is the object whose centre is in the ego lane (``lane == 0``), ahead
(``dx > 0``) and present; a cut-in has one object, so K = 1.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riskcore.criticality.record import CriticalitySettings
from riskcore.sut import kernels as _k
from riskcore.sut.batch import Observations
from riskcore.sut.errors import SutError
from riskcore.sut.protocol import SystemUnderTest

__all__ = ["BUILTIN_SUTS", "SutSpec", "make_sut"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_CC = CriticalitySettings()


def _leader(obs: Observations) -> tuple[BoolArray, FloatArray, FloatArray]:
    """(has a leader, its bumper-to-bumper gap, its speed along x) per run."""
    has = obs.present[:, 0] & (obs.lane[:, 0] == 0) & (obs.dx[:, 0] > 0.0)
    return has, obs.gap[:, 0], obs.vx[:, 0]


class _Base:
    name = "base"

    def __init__(self, **params: float) -> None:
        self.params = params
        self.n = 0
        self.command_onset: FloatArray | None = None

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        self.n = n

    def _brake_from(self, t: FloatArray, t_b: FloatArray, obs: Observations) -> FloatArray:
        """Full braking from the moment t_b (NaN: never): the command of the step that
        contains t_b, with ``command_onset`` = t_b so that the simulator starts it there
        (the criticality record's drivers brake at their exact, interpolated moment)."""
        step = obs.dt if obs.dt > 0 else 0.0
        on = t_b < t + step - 1e-12
        self.command_onset = np.where(on & (t_b > t), t_b, np.nan)
        return np.where(on, -self.params["decel_max"], 0.0)


class NoReaction(_Base):
    """The ego keeps its speed (command 0)."""

    name = "none"

    def compiled(self, ego_v0: FloatArray) -> tuple[int, FloatArray, FloatArray]:
        """The simulator's compiled fast path (kernels.run_builtin)."""
        return _k.K_NONE, np.zeros(1), np.zeros(ego_v0.shape[0])

    def act(self, obs: Observations) -> FloatArray:
        return np.zeros(obs.t.shape[0])


class IDM(_Base):
    """Intelligent Driver Model (Treiber, Hennecke, Helbing 2000)."""

    name = "idm"

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.v0: FloatArray | None = None

    def compiled(self, ego_v0: FloatArray) -> tuple[int, FloatArray, FloatArray]:
        """The simulator's compiled fast path (kernels.run_builtin): (kind, parameters,
        desired speeds) for runs starting at ``ego_v0``."""
        p = self.params
        v0 = p.get("v0", math.nan)
        v_des = (np.maximum(ego_v0, 0.1) if math.isnan(v0)
                 else np.full(ego_v0.shape[0], float(v0)))
        return _k.K_IDM, np.array([p["a"], p["b"], p["T"], p["s0"], p["delta"]]), v_des

    def act(self, obs: Observations) -> FloatArray:
        p = self.params
        v = obs.ego_v
        if self.v0 is None:
            v0 = p.get("v0", math.nan)
            self.v0 = (np.maximum(v, 0.1) if math.isnan(v0)
                       else np.full(v.shape[0], float(v0)))
        has, gap, vl = _leader(obs)
        a_max, b, big_t, s0, delta = p["a"], p["b"], p["T"], p["s0"], p["delta"]
        r = v / self.v0
        free = 1.0 - (r * r) ** 2 if delta == 4.0 else 1.0 - r ** delta
        s = np.maximum(gap, 0.01)
        s_star = s0 + np.maximum(0.0, v * big_t + v * (v - vl) / (2.0 * math.sqrt(a_max * b)))
        inter = np.where(has, (s_star / s) ** 2, 0.0)
        return np.asarray(a_max * (free - inter), dtype=np.float64)


class ACC(_Base):
    """Adaptive cruise control after Xiao, Wang, van Arem (2017), as in de Gelder et al."""

    name = "acc"
    kind = _k.K_ACC

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.v_set: FloatArray | None = None

    def compiled(self, ego_v0: FloatArray) -> tuple[int, FloatArray, FloatArray]:
        """The simulator's compiled fast path (kernels.run_builtin): (kind, parameters,
        set speeds) for runs starting at ``ego_v0``."""
        p = self.params
        vs = p.get("v_set", math.nan)
        v_des = (ego_v0.copy() if math.isnan(vs)
                 else np.full(ego_v0.shape[0], float(vs)))
        q = np.array([p["k0"], p["k1"], p["k2"], p["time_gap"], p["s0"], p["a_min"],
                      p["a_max"], p["range"], p.get("ttc", 0.0), p.get("a_aeb", 0.0)])
        return self.kind, q, v_des

    def acc(self, obs: Observations) -> FloatArray:
        p = self.params
        v = obs.ego_v
        if self.v_set is None:
            vs = p.get("v_set", math.nan)
            self.v_set = v.copy() if math.isnan(vs) else np.full(v.shape[0], float(vs))
        has, gap, vl = _leader(obs)
        cruise = p["k0"] * (self.v_set - v)
        follow = p["k1"] * (gap - p["s0"] - p["time_gap"] * v) + p["k2"] * (vl - v)
        cmd = np.where(has & (gap <= p["range"]), np.minimum(cruise, follow), cruise)
        return np.asarray(np.clip(cmd, p["a_min"], p["a_max"]), dtype=np.float64)

    def act(self, obs: Observations) -> FloatArray:
        return self.acc(obs)


class ACCWithAEB(ACC):
    """ACC plus an automatic emergency brake firing on a TTC threshold."""

    name = "acc_aeb"
    kind = _k.K_ACC_AEB

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.firing = np.zeros(n, dtype=np.bool_)

    def act(self, obs: Observations) -> FloatArray:
        p = self.params
        cmd = self.acc(obs)
        has, gap, vl = _leader(obs)
        clos = obs.ego_v - vl
        with np.errstate(divide="ignore", invalid="ignore"):
            ttc = np.where(has & (clos > 0.0), gap / np.where(clos > 0, clos, 1.0), np.inf)
        self.firing |= ttc < p["ttc"]
        self.firing &= ~(clos <= 0.0) | ~has  # released once the gap stops closing
        self.firing &= has | self.firing
        return np.where(self.firing, -p["a_aeb"], cmd)


def _interp(prev: FloatArray, cur: FloatArray, f: FloatArray) -> FloatArray:
    return np.asarray(prev + (cur - prev) * f, dtype=np.float64)


class R157Careful(_Base):
    """UN R157's careful and competent driver (the criticality record's ``r157_cc``).

    Perception: t_p when the cutter's centre has moved ``wandering_zone`` towards the ego
    lane from its lateral position at the first step (interpolated between steps); from
    t_p on it starts its reaction at the first moment a conflict is developing (the
    cutter ahead and the centre-line gap closed or closing with TTC < ``critical_ttc``,
    +inf: any closing gap), interpolated between steps as the record does; it brakes
    ``reaction_time`` later (command ``-decel_max``; the simulator's jerk limit gives the
    ramp) until standstill.
    """

    name = "r157_cc"

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.t_p = np.full(n, np.nan)
        self.t_r = np.full(n, np.nan)
        self.prev: tuple[FloatArray, ...] | None = None

    def act(self, obs: Observations) -> FloatArray:
        p = self.params
        wz, ttc_c = p["wandering_zone"], p["critical_ttc"]
        dy0 = obs.dy0[:, 0]
        toward = np.where(dy0 > 0.0, -1.0, 1.0)
        move = (obs.dy[:, 0] - dy0) * toward
        t = obs.t
        g = obs.gap[:, 0]
        clos = obs.ego_v - obs.vx[:, 0]
        ahead = obs.dx[:, 0] > 0.0
        cur = (t, move, g, clos, obs.dx[:, 0], obs.ego_v, obs.v[:, 0], obs.psi[:, 0])
        prev = self.prev if self.prev is not None else cur
        # perception, interpolated between the previous step and this one
        new = np.isnan(self.t_p) & (move >= wz)
        if new.any():
            pm = prev[1]
            with np.errstate(divide="ignore", invalid="ignore"):
                f = np.where(move > pm, (wz - pm) / (move - pm), 1.0)
            f = np.where(pm >= wz, 0.0, np.clip(f, 0.0, 1.0))
            self.t_p[new] = _interp(prev[0], t, f)[new]
            # the state at t_p (linear between the steps) is the first one checked
            at_g = _interp(prev[2], g, f)
            # as the record: the speeds and the heading interpolated, then combined
            at_c = (_interp(prev[5], obs.ego_v, f)
                    - _interp(prev[6], obs.v[:, 0], f) * np.cos(_interp(prev[7], obs.psi[:, 0], f)))
            at_ahead = _interp(prev[4], obs.dx[:, 0], f) > 0.0
            crit = self._critical(at_ahead, at_g, at_c, ttc_c)
            fresh = new & crit
            self.t_r[fresh] = self.t_p[fresh]
            # where not critical at t_p: the margin at t_p is the previous point
            prev = (np.where(new, self.t_p, prev[0]), prev[1], np.where(new, at_g, prev[2]),
                    np.where(new, at_c, prev[3]), *prev[4:])
        look = ~np.isnan(self.t_p) & np.isnan(self.t_r) & (t > self.t_p)
        if look.any():
            crit = self._critical(ahead, g, clos, ttc_c)
            hit = look & crit
            if hit.any():
                f_prev = self._margin(prev[2], prev[3], ttc_c)
                f_cur = self._margin(g, clos, ttc_c)
                interp = (g > 0.0) & (f_prev > 0.0) & (f_cur < f_prev)
                with np.errstate(divide="ignore", invalid="ignore"):
                    t_root = prev[0] + (t - prev[0]) * f_prev / (f_prev - f_cur)
                self.t_r[hit] = np.where(interp, t_root, t)[hit]
        self.prev = cur
        return self._brake_from(t, self.t_r + p["reaction_time"], obs)

    @staticmethod
    def _critical(ahead: BoolArray, g: FloatArray, clos: FloatArray,
                  ttc_c: float) -> BoolArray:
        if ttc_c == math.inf:
            return np.asarray(ahead & ((g <= 0.0) | (clos > 0.0)), dtype=np.bool_)
        return np.asarray(ahead & ((g <= 0.0) | ((clos > 0.0) & (g < ttc_c * clos))),
                          dtype=np.bool_)

    @staticmethod
    def _margin(g: FloatArray, clos: FloatArray, ttc_c: float) -> FloatArray:
        if ttc_c == math.inf:
            return np.asarray(-clos, dtype=np.float64)
        return np.asarray(g - ttc_c * clos, dtype=np.float64)


class RSS(_Base):
    """RSS longitudinal response (Shalev-Shwartz et al. 2017), as the record's ``rss``:
    once the longitudinal and the lateral safe distances are both violated it brakes
    after the response time rho (command ``-decel_max``) until standstill. The trigger
    is found by bisection between steps on the linearly interpolated observations."""

    name = "rss"

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.t_trig = np.full(n, np.nan)
        self.prev: tuple[FloatArray, ...] | None = None

    def _danger(self, obs: Observations, dx: FloatArray, dy: FloatArray, psi: FloatArray,
                vc: FloatArray, ve: FloatArray) -> BoolArray:
        p = self.params
        rho, a_acc, b_min, b_max = p["rho"], p["a_accel"], p["b_min"], p["b_max"]
        mu, a_lat = p["mu"], p["a_lat"]
        ehl, ehw = 0.5 * obs.ego_length, 0.5 * obs.ego_width
        chl, chw = 0.5 * obs.length[:, 0], 0.5 * obs.width[:, 0]
        c, sn = np.cos(psi), np.sin(psi)
        vf = np.maximum(vc * c, 0.0)
        d_long = (ve * rho + 0.5 * a_acc * rho * rho + (ve + rho * a_acc) ** 2 / (2 * b_min)
                  - vf * vf / (2 * b_max))
        lon_bad = (dx > 0.0) & (dx - ehl - chl < d_long)
        lat_gap = np.abs(dy) - ehw - (chl * np.abs(sn) + chw * np.abs(c))
        toward = np.maximum(np.where(dy > 0.0, -vc * sn, vc * sn), 0.0)
        d_lat = (mu + (2.0 * toward + a_lat * rho) * rho / 2.0
                 + (toward + a_lat * rho) ** 2 / (2.0 * a_lat))
        return np.asarray(lon_bad & (lat_gap < d_lat), dtype=np.bool_)

    def act(self, obs: Observations) -> FloatArray:
        p = self.params
        cur = (obs.t, obs.dx[:, 0], obs.dy[:, 0], obs.psi[:, 0], obs.v[:, 0], obs.ego_v)
        first = self.prev is None
        prev = cur if self.prev is None else self.prev
        look = np.isnan(self.t_trig)
        if look.any():
            bad = look & self._danger(obs, *cur[1:])
            if bad.any():
                idx = np.flatnonzero(bad)
                if first:
                    self.t_trig[idx] = obs.t[idx]
                else:
                    lo = np.zeros(idx.shape[0])
                    hi = np.ones(idx.shape[0])
                    pv = [q[idx] for q in prev]
                    cv = [q[idx] for q in cur]
                    sub = _Sub(obs, idx)
                    for _ in range(52):
                        mid = 0.5 * (lo + hi)
                        st = [_interp(a, b, mid) for a, b in zip(pv, cv, strict=True)]
                        d = self._danger(sub, *st[1:])  # type: ignore[arg-type]
                        hi = np.where(d, mid, hi)
                        lo = np.where(d, lo, mid)
                    self.t_trig[idx] = _interp(pv[0], cv[0], hi)
        self.prev = cur
        return self._brake_from(obs.t, self.t_trig + p["rho"], obs)


class _Sub:
    """The sizes of some runs of an observation (for :meth:`RSS._danger`)."""

    def __init__(self, obs: Observations, idx: NDArray[np.intp]) -> None:
        self.ego_length = obs.ego_length
        self.ego_width = obs.ego_width
        self.length = obs.length[idx]
        self.width = obs.width[idx]


class TTRAEB(_Base):
    """An emergency brake on Wagner's r_dep of the current scene, computed online.

    Every ``period`` s (whole steps of the update period) the scene "the ego at constant
    speed over riskcore's horizon, the object's current state" is scored by riskcore's
    engine (the criticality record's compiled one-object path; the object's yaw rate
    from its last two observed headings); once r_dep >= ``threshold`` it brakes at
    ``a_aeb`` until the gap stops closing. Otherwise it keeps its speed. Costly: one
    Monte-Carlo scene (~1 ms) per run and period while an object is near.
    """

    name = "ttr_aeb"

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        super().reset(n, seeds)
        self.firing = np.zeros(n, dtype=np.bool_)
        self.prev_psi: FloatArray | None = None
        self.prev_t: FloatArray | None = None
        self.next_t = np.zeros(n)
        from riskcore.evasion import MANOEUVRES
        from riskcore.scene import _Engine, default_surfaces
        from riskcore.settings import RiskSettings

        self._rs = RiskSettings()
        self._surf = default_surfaces()
        self._eng = _Engine(self._rs, self._surf, MANOEUVRES)
        self._man = MANOEUVRES

    def act(self, obs: Observations) -> FloatArray:
        from riskcore.criticality import kernels as _ck

        p = self.params
        t = obs.t
        psi = obs.psi[:, 0]
        if self.prev_psi is None or self.prev_t is None:
            w0 = np.zeros_like(psi)
        else:
            dt = np.where(t > self.prev_t, t - self.prev_t, 1.0)
            w0 = (psi - self.prev_psi) / dt
        self.prev_psi, self.prev_t = psi.copy(), t.copy()
        has, _, vl = _leader(obs)
        clos = obs.ego_v - vl
        self.firing &= ~(has & (clos <= 0.0))
        near = (obs.present[:, 0] & ~self.firing & (t >= self.next_t - 1e-9)
                & (obs.dx[:, 0] > -obs.length[:, 0]) & (obs.dx[:, 0] < p["reach"])
                & (np.abs(obs.dy[:, 0]) < 2.0 * obs.lane_width))
        rs = self._rs
        n_h = rs.n_steps
        off = np.arange(n_h + 1, dtype=np.float64) * rs.dt
        eng = self._eng
        for i in np.flatnonzero(near):
            v = float(obs.ego_v[i])
            ex = np.asarray(v * off, dtype=np.float64)
            ev = np.full(n_h + 1, v)
            zeros = np.zeros(n_h + 1)
            man_a = np.empty((n_h, len(self._man)))
            man_w = np.empty((n_h, len(self._man)))
            for j, man in enumerate(self._man):
                man_a[:, j], man_w[:, j] = man.inputs(ev[:n_h], rs)
            ov = float(obs.v[i, 0])
            ma, sa = self._surf.accel.at(ov, float(obs.a[i, 0]))
            mw, sw = self._surf.turn.at(ov, float(w0[i]))
            r = _ck.scene_risk(float(obs.dx[i, 0]), float(obs.dy[i, 0]), float(psi[i]), ov,
                               float(ma), float(sa), float(mw), float(sw), eng._za, eng._zw,
                               eng._weight, 0.5 * float(obs.length[i, 0]),
                               0.5 * float(obs.width[i, 0]), ex, zeros, zeros.copy(), ev,
                               0.5 * obs.ego_length, 0.5 * obs.ego_width, man_a, man_w,
                               rs.dt, rs.t_pnr, rs.t_max, rs.m)
            if r >= p["threshold"]:
                self.firing[i] = True
        self.next_t = np.where(near, t + p["period"], self.next_t)
        return np.where(self.firing, -p["a_aeb"], 0.0)


@dataclass(frozen=True)
class SutSpec:
    """A built-in SUT: its name, a one-line summary, its parameters (name -> (default,
    unit, meaning)), the source, and the factory ``factory(**params)``."""

    name: str
    summary: str
    parameters: dict[str, tuple[float, str, str]]
    source: str
    factory: Callable[..., SystemUnderTest] = field(repr=False)

    def defaults(self) -> dict[str, float]:
        return {k: v[0] for k, v in self.parameters.items()}


def _factory(cls: type[_Base], name: str,
             parameters: dict[str, tuple[float, str, str]]) -> Callable[..., SystemUnderTest]:
    def make(**params: float) -> SystemUnderTest:
        unknown = sorted(set(params) - set(parameters))
        if unknown:
            raise SutError(f"{name}: unknown parameter(s) {', '.join(unknown)}; known: "
                           f"{', '.join(parameters) or 'none'}")
        values = {k: v[0] for k, v in parameters.items()}
        for k, val in params.items():
            if isinstance(val, bool) or not isinstance(val, int | float):
                raise SutError(f"{name}.{k}: expected a number, got {val!r}")
            values[k] = float(val)
        sut = cls(**values)
        sut.name = name
        return sut  # type: ignore[return-value]

    return make


_R157_PARAMS: dict[str, tuple[float, str, str]] = {
    "wandering_zone": (_CC.wandering_zone, "m", "lateral movement towards the ego lane "
                       "that makes the cut-in perceived (1.095 = 0.375 + 0.72: the "
                       "esmini-matching perception)"),
    "reaction_time": (_CC.reaction_time, "s", "from the reaction's start to braking"),
    "decel_max": (_CC.decel_max, "m/s²", "full deceleration 0.774 g (ramped by the "
                  "simulator's jerk limit, 12.65 m/s³ by default)"),
}
_RSS_PARAMS: dict[str, tuple[float, str, str]] = {
    "rho": (_CC.rss_response_time, "s", "response time"),
    "a_accel": (_CC.rss_accel_max, "m/s²", "worst-case acceleration during rho"),
    "b_min": (_CC.rss_brake_min, "m/s²", "braking the ego guarantees"),
    "b_max": (_CC.rss_brake_max, "m/s²", "hardest braking of the vehicle ahead"),
    "mu": (_CC.rss_lat_margin, "m", "lateral fluctuation margin"),
    "a_lat": (_CC.rss_lat_accel_max, "m/s²", "lateral acceleration of the cutter"),
    "decel_max": (_CC.decel_max, "m/s²", "the response's deceleration"),
}
_ACC_PARAMS: dict[str, tuple[float, str, str]] = {
    "k0": (0.4, "1/s", "speed-control gain (cruising)"),
    "k1": (0.23, "1/s²", "gap-control gain on the spacing error"),
    "k2": (0.07, "1/s", "gap-control gain on the speed difference"),
    "time_gap": (1.1, "s", "desired time gap"),
    "s0": (2.0, "m", "standstill distance (ours)"),
    "a_min": (-6.0, "m/s²", "strongest ACC deceleration"),
    "a_max": (2.0, "m/s²", "strongest ACC acceleration (ours)"),
    "range": (120.0, "m", "gap control only for a leader within this gap"),
    "v_set": (math.nan, "m/s", "set speed (NaN: the ego's initial speed)"),
}

_IDM_PARAMS: dict[str, tuple[float, str, str]] = {
    "v0": (math.nan, "m/s", "desired speed (NaN: the ego's initial speed)"),
    "T": (1.6, "s", "desired time headway"),
    "s0": (2.0, "m", "standstill distance"),
    "a": (0.73, "m/s²", "maximum acceleration"),
    "b": (1.67, "m/s²", "comfortable deceleration"),
    "delta": (4.0, "-", "acceleration exponent"),
}
_AEB_PARAMS: dict[str, tuple[float, str, str]] = {
    **_ACC_PARAMS,
    "ttc": (1.5, "s", "AEB fires when the TTC to the leader falls below this"),
    "a_aeb": (9.0, "m/s²", "AEB deceleration (held until the gap stops closing)"),
}


_TTR_PARAMS: dict[str, tuple[float, str, str]] = {
    "threshold": (0.5, "-", "brake once r_dep of the current scene reaches this"),
    "a_aeb": (9.0, "m/s²", "brake deceleration (held until the gap stops closing)"),
    "period": (0.1, "s", "r_dep is computed at most this often per run (cost)"),
    "reach": (100.0, "m", "only objects with dx below this are scored"),
}


def _spec(name: str, summary: str, parameters: dict[str, tuple[float, str, str]],
          source: str, cls: type[_Base]) -> SutSpec:
    return SutSpec(name, summary, parameters, source, _factory(cls, name, parameters))


BUILTIN_SUTS: Mapping[str, SutSpec] = {
    spec.name: spec for spec in (
        _spec("none", "the ego keeps its initial speed", {},
              "reference: the criticality record's scripted ego", NoReaction),
        _spec("r157_cc", "UN R157 careful and competent driver, JRC-FSM rule: after "
              "perceiving the cut-in it waits for TTC < 2 s, then reacts",
              {**_R157_PARAMS, "critical_ttc": (2.0, "s", "reacts only once TTC is below "
                                                "this (re-checked every step)")},
              "UN R157 Annex 4 Appendix 3; Mattas et al. 2022 (AAP 174, 106743) and "
              "their implementation ec-jrc/JRC-FSM", R157Careful),
        _spec("r157_cc_conflict", "UN R157 careful driver, scengen's 'conflict developing' "
              "rule: reacts at t_p when the gap closes (the criticality record's default)",
              {**_R157_PARAMS, "critical_ttc": (math.inf, "s", "TTC gate (inf: any closing "
                                                "gap)")},
              "UN R157 Annex 4 Appendix 3; docs/criticality.md", R157Careful),
        _spec("rss", "RSS longitudinal response", _RSS_PARAMS,
              "Shalev-Shwartz, Shammah, Shashua 2017; values of Mattas et al. 2022", RSS),
        _spec("idm", "Intelligent Driver Model, desired speed = the ego's initial speed",
              _IDM_PARAMS, "Treiber, Hennecke, Helbing 2000, Phys. Rev. E 62, 1805 "
              "(their highway values)", IDM),
        _spec("acc", "adaptive cruise control (gap and speed control)", _ACC_PARAMS,
              "Xiao, Wang, van Arem 2017, TRR 2623; gains and a_min as in de Gelder et al. "
              "(TNO)", ACC),
        _spec("acc_aeb", "acc plus an emergency brake at TTC < ttc", _AEB_PARAMS,
              "acc above; the AEB threshold is our choice", ACCWithAEB),
        _spec("ttr_aeb", "keeps its speed; emergency brake once Wagner's online r_dep of the "
              "current scene reaches a threshold", _TTR_PARAMS,
              "Wagner et al. (seed 000) risk as an online monitor; riskcore's engine and "
              "defaults (Table II)", TTRAEB),
    )
}


def make_sut(name: str, **params: Any) -> SystemUnderTest:
    """A built-in SUT by name with its parameters (defaults in ``BUILTIN_SUTS``)."""
    try:
        spec = BUILTIN_SUTS[name]
    except KeyError:
        raise SutError(f"sut: unknown built-in {name!r}; known: "
                       f"{', '.join(BUILTIN_SUTS)}") from None
    return spec.factory(**params)
