"""Criticality straight from parameter vectors: derived quantities for the constraints.

``criticality_quantities(params, lane_width)`` gives, for many cut-in vectors at once, the
values :func:`riskcore.criticality.evaluate_criticality` would give for the scenario that
:func:`sampler.scenario.builder.build_scenario` builds from each vector (default lead-in, step and
vehicle sizes), without building it:

=====================  =====  ===================================================
name                   unit   meaning (docs/criticality.md)
=====================  =====  ===================================================
``t_p``                s      perception moment, scenario time (lead-in 2.5 s)
``a_req``              m/s²   deceleration needed from t_p + 0.75 s (0, inf)
``btn``                -      a_req / (0.774 g)
``ttr_true``           s      TTR at t_p on the cutter's actual path (inf, 0)
``r157_collision``     -      1 if the R157 careful driver hits the cutter, else 0
``r157_impact_speed``  m/s    its relative impact speed (0 without contact)
``none_collision``     -      1 if the scripted (constant-speed) ego hits it, else 0
=====================  =====  ===================================================

How: one compiled loop over the vectors. For each it integrates the cutter's motion
(``datasets.cutin_model``: closed-form heading and speed, positions by Simpson's rule on
0.05 s halves) at the builder's sample times and runs the drivers on the same 0.01 s
simulation grid the scenario-level code uses (linear between samples) with the pruned
kernels of :mod:`riskcore.criticality.kernels` (``drive_pruned``,
``r157_reaction_start_pruned``, ``required_decel_pruned``: a bound per 0.1 s sample
interval rules most intervals out; docs/criticality.md), then riskcore's TTR scan when
asked. ``baseline=True`` runs the grid kernels over every 0.01 s step instead (the
earlier path; same values to rounding). A row that is not a buildable cut-in (no
crossing, non-positive ego speed, a negative cutter speed) gives NaN.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from datasets import DEFAULT_LANE_WIDTH
from riskcore import MANOEUVRES, RiskSettings, jit
from riskcore import kernels as _kernels
from riskcore.criticality import CriticalitySettings
from riskcore.criticality import kernels as _ck
from sampler.errors import SamplerError
from sampler.region.kinematics import crossing_kinematics
from sampler.scenario.builder import (
    DEFAULT_DT,
    DEFAULT_LEAD_IN,
    DEFAULT_VEHICLE_SIZE,
    MAX_DURATION,
)

jit.register(__file__)  # before the first @njit: one cache per version of the kernels

__all__ = ["CRITICALITY_QUANTITIES", "criticality_quantities"]

FloatArray = NDArray[np.float64]

#: name -> (unit, meaning), in the column order of the kernel's output
CRITICALITY_QUANTITIES: dict[str, tuple[str, str]] = {
    "t_p": ("s", "perception moment (cutter moved 0.375 m towards the ego lane), scenario "
            "time"),
    "a_req": ("m/s^2", "constant deceleration needed when braking starts 0.75 s after t_p"),
    "btn": ("-", "brake threat number a_req / (0.774 g)"),
    "ttr_true": ("s", "time to react at t_p against the cutter's actual path"),
    "r157_collision": ("-", "1 if the UN R157 careful driver hits the cutter, else 0"),
    "r157_impact_speed": ("m/s", "the R157 driver's relative impact speed (0: none)"),
    "none_collision": ("-", "1 if the ego at constant speed hits the cutter, else 0"),
}

# the builder's defaults (numba reads module globals as compile-time constants)
_LEAD_IN = DEFAULT_LEAD_IN
_DT = DEFAULT_DT
_SIZE = DEFAULT_VEHICLE_SIZE
_MAX_DURATION = MAX_DURATION


@numba.njit(cache=True)
def _state(p_y1: float, p_t: float, p_a1: float, p_a2: float, p_a3: float, p_v0: float,
           tau: float) -> tuple[float, float, float]:  # pragma: no cover - jit
    """Heading (rad), speed (m/s) at the model's time tau; and the yaw-rate-free check."""
    if 0.0 <= tau <= 2.0 * p_t:
        psi = p_y1 * p_t / math.pi * (1.0 - math.cos(math.pi * tau / p_t))
    else:
        psi = 0.0
    c = min(max(tau - p_a2, 0.0), p_a3)
    c0 = min(max(-p_a2, 0.0), p_a3)
    return psi, p_v0 + p_a1 * (c - c0), 0.0


class _Cutter(NamedTuple):
    """The built scenario's cutter for one row (:func:`_cutter_samples`)."""

    t_p: float  # perception moment, scenario time; NaN: not a buildable cut-in
    v_e: float  # the ego's constant speed
    t_stop: float  # end of the simulated time
    s: FloatArray  # centre along the ego's path (the road's x axis at y = 0) ...
    d: FloatArray  # ... and across it, at the sample times k * _DT
    p: FloatArray  # heading there
    v: FloatArray  # speed there (straight at constant speed after the last sample)


class _Box(NamedTuple):
    """Half lengths and half widths of the ego and the cutter (m)."""

    ehl: float
    ehw: float
    chl: float
    chw: float


class _Settings(NamedTuple):
    """The drivers' and the TTR scan's settings (``criticality_quantities`` packs them)."""

    wz: float  # wandering zone: the cutter's lateral move that marks t_p
    reaction: float
    jerk: float
    a_max: float
    ttc_crit: float
    h: float  # simulation step
    tail: float
    follow: float
    ttr_dt: float
    ttr_tail: float  # negative: no TTR scan
    grid: bool  # the baseline path (grid kernels over every step)


@numba.njit(cache=True)
def _not_a_cut_in() -> _Cutter:  # pragma: no cover - jit
    """The answer for a row that is not a buildable cut-in (t_p NaN)."""
    empty = np.empty(0)
    return _Cutter(np.nan, np.nan, np.nan, empty, empty, empty, empty)


@numba.njit(cache=True)
def _row_state(row: FloatArray, tau: float) -> tuple[float, float]:  # pragma: no cover
    """The cutter's heading and speed at the model's time tau."""
    psi, v, _ = _state(row[0], row[1], row[2], row[3], row[4], row[5], tau)
    return psi, v


@numba.njit(cache=True)
def _n_samples(row: FloatArray) -> int:  # pragma: no cover - jit
    """The number of sample times (every _DT up to the settled motion + _DT) of a row the
    builder accepts; 0 for a row it refuses (not finite, no lateral motion, too long)."""
    for j in range(8):
        if not math.isfinite(row[j]):
            return 0
    p_y1, p_t, p_a2, p_a3 = row[0], row[1], row[3], row[4]
    if p_t <= 0.0 or p_a3 < 0.0 or p_y1 == 0.0:
        return 0
    pulse_end = p_a2 + p_a3 if p_a3 > 0.0 else 0.0
    t_settle = _LEAD_IN + max(2.0 * p_t, pulse_end, 0.0)
    if t_settle > _MAX_DURATION:  # the builder refuses it
        return 0
    k_set = math.ceil(t_settle / _DT - 1e-9) + 1
    return k_set + 1


@numba.njit(cache=True)
def _velocity(psi: float, v: float) -> tuple[float, float]:  # pragma: no cover - jit
    """The velocity's components; straight (psi 0): no trigonometry."""
    if psi == 0.0:
        return v, 0.0
    return v * math.cos(psi), v * math.sin(psi)


@numba.njit(cache=True)
def _half_step(row: FloatArray, start: tuple[float, float, float], f0: tuple[float, float],
               hs: float) -> tuple[float, float, float, float, float, float, float, float,
                                   float]:  # pragma: no cover - jit
    """Simpson's rule over one half sample step of length hs from ``start`` (x, y, tau),
    the velocity there ``f0``. Returns the position at the step's middle (quadratic
    through the three points) and end, the heading and speed at the end, the velocity
    there, and the speed at the middle: (x_m, y_m, x1, y1, psi1, v1, fx1, fy1, v_m)."""
    x, y, tau = start
    fx0, fy0 = f0
    pm, vm = _row_state(row, tau + 0.5 * hs)
    p1, v1 = _row_state(row, tau + hs)
    fxm, fym = _velocity(pm, vm)
    fx1, fy1 = _velocity(p1, v1)
    y_m = y + hs / 24.0 * (5.0 * fy0 + 8.0 * fym - fy1)  # quadratic through 3 pts
    x_m = x + hs / 24.0 * (5.0 * fx0 + 8.0 * fxm - fx1)
    y1 = y + hs / 6.0 * (fy0 + 4.0 * fym + fy1)
    x1 = x + hs / 6.0 * (fx0 + 4.0 * fxm + fx1)
    return x_m, y_m, x1, y1, p1, v1, fx1, fy1, vm


@numba.njit(cache=True)
def _crossing(offset: float, tau: float, hs: float, p0: tuple[float, float],
              pm: tuple[float, float],
              p1: tuple[float, float]) -> tuple[float, float]:  # pragma: no cover - jit
    """The crossing moment and x there within a half step from tau whose end p1 (x, y)
    is past ``offset``: linear in |y| on the step's two quarters (p0 start, pm middle;
    |y| rises monotonically here)."""
    x, y = p0
    x_m, y_m = pm
    x1, y1 = p1
    if abs(y_m) >= offset:
        f = (offset - abs(y)) / (abs(y_m) - abs(y)) if abs(y_m) > abs(y) else 0.0
        return tau + f * 0.5 * hs, x + f * (x_m - x)
    f = (offset - abs(y_m)) / (abs(y1) - abs(y_m))
    return tau + 0.5 * hs + f * 0.5 * hs, x_m + f * (x1 - x_m)


@numba.njit(cache=True)
def _integrate(row: FloatArray, lane_width: float, n_s: int
               ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float,
                          float]:  # pragma: no cover - jit
    """The cutter's motion from tau = -lead_in at n_s sample times every _DT (0.05 s
    halves, Simpson's rule), relative to its start: (x, y, heading, speed, tau_c, x_c),
    with the crossing moment tau_c (NaN: none within [0, 2 p_t], or a negative speed)
    and x there, found on the quarter-step grid by linear interpolation of |y| (the
    builder: 1 ms, linear)."""
    sx = np.empty(n_s)
    sy = np.empty(n_s)
    sp = np.empty(n_s)
    sv = np.empty(n_s)
    hs = _DT / 2.0
    x = 0.0
    y = 0.0
    tau = -_LEAD_IN
    psi, v = _row_state(row, tau)
    sx[0], sy[0], sp[0], sv[0] = 0.0, 0.0, psi, v
    offset = lane_width / 2.0
    tau_c = np.nan
    x_c = 0.0
    fx0 = v * math.cos(psi)
    fy0 = v * math.sin(psi)
    for k in range(1, n_s):
        for _ in range(2):
            x_m, y_m, x1, y1, p1, v1, fx1, fy1, vm = _half_step(row, (x, y, tau),
                                                                (fx0, fy0), hs)
            if math.isnan(tau_c) and tau + hs >= 0.0 and abs(y1) >= offset:
                tau_c, x_c = _crossing(offset, tau, hs, (x, y), (x_m, y_m), (x1, y1))
                if tau_c > 2.0 * row[1]:
                    tau_c = np.nan
            x, y, tau, psi, v = x1, y1, tau + hs, p1, v1
            fx0, fy0 = fx1, fy1
            if v < 0.0 or vm < 0.0:
                return sx, sy, sp, sv, np.nan, x_c
        sx[k], sy[k], sp[k], sv[k] = x, y, psi, v
    return sx, sy, sp, sv, tau_c, x_c


@numba.njit(cache=True)
def _stop_time(sx: FloatArray, sp: FloatArray, sv: FloatArray, x_cut0: float, v_e: float,
               tail: float, follow: float) -> float:  # pragma: no cover - jit
    """The end of the simulated time: the scenario-level frames simulate tail + (time
    to close the gap after the last sample, at most follow)."""
    n_s = sx.shape[0]
    ehl = 0.5 * _SIZE[0]
    t_end = (n_s - 1) * _DT
    vx_end = sv[n_s - 1] * math.cos(sp[n_s - 1])
    gap_end = x_cut0 + sx[n_s - 1] - v_e * t_end - 2.0 * ehl
    closing = v_e - vx_end
    extra = gap_end / closing if closing > 0.0 and gap_end > 0.0 else 0.0
    return t_end + tail + min(extra, follow)


@numba.njit(cache=True)
def _perception(sy: FloatArray, wz: float) -> float:  # pragma: no cover - jit
    """The perception moment: the centre has moved wz towards the ego lane (samples,
    linear); NaN: never."""
    for k in range(1, sy.shape[0]):
        if abs(sy[k]) >= wz:
            return (k - 1) * _DT + (wz - abs(sy[k - 1])) / (abs(sy[k]) - abs(sy[k - 1])) * _DT
    return np.nan


@numba.njit(cache=True)
def _cutter_samples(row: FloatArray, lane_width: float, wz: float, tail: float,
                    follow: float) -> _Cutter:  # pragma: no cover - jit
    """The built scenario's cutter for one row, without building it.

    Returns the perception moment (scenario time), the ego's constant speed, the end of
    the simulated time, and the cutter's centre (along and across the ego's path, which
    is the road's x axis at y = 0), heading and speed at the builder's sample times
    k * 0.1 s, k = 0 .. n - 1 (straight at constant speed after the last one): a
    :class:`_Cutter`, whose t_p is NaN when the row is not a buildable cut-in.
    """
    n_s = _n_samples(row)
    if n_s == 0:
        return _not_a_cut_in()
    # integrate on 0.01 s substeps from tau = -lead_in over the lateral motion and beyond:
    # samples every _DT up to t_settle + 0.1, then constant velocity (as the frames do)
    sx, sy, sp, sv, tau_c, x_c = _integrate(row, lane_width, n_s)
    if math.isnan(tau_c):
        return _not_a_cut_in()
    _, v_cut_c = _row_state(row, tau_c)
    v_e = v_cut_c + row[6]
    if not v_e > 0.0:
        return _not_a_cut_in()
    ehl = 0.5 * _SIZE[0]
    t_c = _LEAD_IN + tau_c
    # the x integral starts at tau = -lead_in, the builder's at tau = 0: only differences
    # matter (x_cut0 is chosen from the same integral at the crossing)
    x_cut0 = row[7] + 2.0 * ehl + v_e * t_c - x_c
    y_start = -lane_width if row[0] > 0.0 else lane_width
    t_stop = _stop_time(sx, sp, sv, x_cut0, v_e, tail, follow)
    t_p = _perception(sy, wz)
    if math.isnan(t_p):
        return _not_a_cut_in()
    for k in range(n_s):
        sx[k] += x_cut0
        sy[k] += y_start
    return _Cutter(t_p, v_e, t_stop, sx, sy, sp, sv)


@numba.njit(cache=True)
def _ttr_scene(cut: _Cutter, n_t: int, ttr_dt: float
               ) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - jit
    """The ego's poses and speeds and the cutter's trajectory at t_p + i ttr_dt, i = 0 ..
    n_t, as riskcore's TTR scan takes them (ego frame = road frame here); the cutter
    straight at constant speed after its last sample."""
    cs, cd, cp, cv, v_e = cut.s, cut.d, cut.p, cut.v, cut.v_e
    n_s = cs.shape[0]
    t_end = (n_s - 1) * _DT
    vx_end = cv[n_s - 1] * math.cos(cp[n_s - 1])
    poses = np.zeros((n_t + 1, 4))
    vv = np.full(n_t + 1, v_e)
    traj = np.empty((1, n_t + 1, 4))
    for i in range(n_t + 1):
        tq = cut.t_p + i * ttr_dt
        poses[i, 0] = v_e * tq
        poses[i, 2] = 1.0
        if tq > t_end:  # straight at constant speed after the last sample
            traj[0, i, 0] = cs[n_s - 1] + vx_end * (tq - t_end)
            traj[0, i, 1] = cd[n_s - 1]
            pq = cp[n_s - 1]
        else:
            traj[0, i, 0] = _ck.interp(cs, 0.0, _DT, tq)
            traj[0, i, 1] = _ck.interp(cd, 0.0, _DT, tq)
            pq = _ck.interp(cp, 0.0, _DT, tq)
        traj[0, i, 2] = math.cos(pq)
        traj[0, i, 3] = math.sin(pq)
    return poses, vv, traj


@numba.njit(cache=True)
def _ttr_at_tp(cut: _Cutter, c_none: float, man_a1: FloatArray, man_w1: FloatArray,
               box: _Box, ttr_dt: float, ttr_tail: float) -> float:  # pragma: no cover
    """riskcore's TTR scan at t_p against the actual path (ego frame = road frame here);
    the cutter given by its samples every _DT, straight at constant speed after them."""
    n_t = math.ceil((c_none - cut.t_p) / ttr_dt - 1e-9) + math.ceil(ttr_tail / ttr_dt)
    n_t = max(1, min(n_t, 1000))
    poses, vv, traj = _ttr_scene(cut, n_t, ttr_dt)
    n_man = man_a1.shape[0]
    man_a = np.empty((n_t, n_man))
    man_w = np.empty((n_t, n_man))
    for i in range(n_t):
        for m in range(n_man):
            man_a[i, m] = man_a1[m]
            man_w[i, m] = man_w1[m]
    eva = np.empty((n_t, n_man, n_t + 1, 4))
    done = np.zeros((n_t, n_man), dtype=np.bool_)
    first, react, _ = _kernels.ttr_scan(traj, box.chl, box.chw, poses, vv, box.ehl, box.ehw,
                                        man_a, man_w, ttr_dt, eva, done)
    if first[0] < 0:
        return np.inf
    if react[0] < 0:
        return 0.0
    return react[0] * ttr_dt


@numba.njit(cache=True)
def _drivers_pruned(cut: _Cutter, box: _Box, cfg: _Settings
                    ) -> tuple[float, float, float, float, float]:  # pragma: no cover - jit
    """The fast path: the pruned kernels on the samples (stepping at h only through the
    sample intervals that a bound cannot rule out). Returns (none contact, its impact
    speed, R157 contact, its impact speed, a_req)."""
    cs_s, cd_s, cp_s, cv_s = cut.s, cut.d, cut.p, cut.v
    ehl, ehw, chl, chw = box
    n_s = cs_s.shape[0]
    ratio = round(_DT / cfg.h)
    es_s = np.empty(n_s)
    for k in range(n_s):
        es_s[k] = cut.v_e * (k * _DT)
    ev_s = np.full(n_s, cut.v_e)
    c_none, imp_none = _ck.drive_pruned(0.0, _DT, ratio, cs_s, cd_s, cp_s, cv_s, es_s, ev_s,
                                        ehl, ehw, chl, chw, np.nan, cfg.jerk, cfg.a_max, 0,
                                        True, cut.t_stop)
    t_r = _ck.r157_reaction_start_pruned(0.0, _DT, ratio, cs_s, cp_s, cv_s, es_s, ev_s,
                                         ehl + chl, cut.t_p, cfg.ttc_crit, True, cut.t_stop)
    t_b = t_r + cfg.reaction
    if math.isnan(t_b) or (not math.isnan(c_none) and c_none <= t_b):
        # never brakes, or the contact comes before the brakes: the scripted ego's
        c_r, imp_r = c_none, imp_none
    else:
        # until t_b the R157 ego is the scripted one, which has no contact before
        # c_none: start its run at the grid step before t_b
        kb = max(math.floor(t_b / cfg.h) - 1, 0)
        c_r, imp_r = _ck.drive_pruned(0.0, _DT, ratio, cs_s, cd_s, cp_s, cv_s, es_s, ev_s,
                                      ehl, ehw, chl, chw, t_b, cfg.jerk, cfg.a_max, kb,
                                      True, cut.t_stop)
    a_req = 0.0
    if not math.isnan(c_none):
        t_b0 = cut.t_p + cfg.reaction
        a_req = np.inf if c_none <= t_b0 else _ck.required_decel_pruned(
            0.0, _DT, ratio, cs_s, cd_s, cp_s, cv_s, es_s, ev_s, ehl, ehw, chl, chw,
            t_b0, True)
    return c_none, imp_none, c_r, imp_r, a_req


@numba.njit(cache=True)
def _one(row: FloatArray, lane_width: float, man_a1: FloatArray, man_w1: FloatArray,
         out: FloatArray, cfg: _Settings) -> None:  # pragma: no cover - jit
    """The quantities of one row into ``out`` (NaN: not a cut-in).

    ``cfg.grid`` False (the fast path): the pruned kernels on the samples. True (the
    baseline): the samples put on the h grid, then the grid kernels over it, as the
    scenario level does.
    """
    for j in range(out.shape[0]):
        out[j] = np.nan
    cut = _cutter_samples(row, lane_width, cfg.wz, cfg.tail, cfg.follow)
    if math.isnan(cut.t_p):
        return
    ehl = 0.5 * _SIZE[0]
    ehw = 0.5 * _SIZE[1]
    box = _Box(ehl, ehw, ehl, ehw)
    out[0] = cut.t_p
    if cfg.grid:
        c_none, _, c_r, imp_r, a_req = _drivers_grid(cut, box, cfg)
    else:
        c_none, _, c_r, imp_r, a_req = _drivers_pruned(cut, box, cfg)
    out[4] = 0.0 if math.isnan(c_r) else 1.0
    out[5] = imp_r
    out[6] = 0.0 if math.isnan(c_none) else 1.0
    if math.isnan(c_none):
        out[1] = 0.0
        out[2] = 0.0
        out[3] = np.inf
        return
    out[1] = a_req
    out[2] = a_req / cfg.a_max
    if cfg.ttr_tail < 0.0:  # the TTR scan is not wanted
        return
    out[3] = _ttr_at_tp(cut, c_none, man_a1, man_w1, box, cfg.ttr_dt, cfg.ttr_tail)


@numba.njit(cache=True)
def _on_grid(cut: _Cutter, h: float
             ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                        FloatArray]:  # pragma: no cover - jit
    """The cutter's samples put on the h grid (linear between them) and the scripted
    ego's position and speed there: (cs, cd, cp, cv, es, ev)."""
    cs_s, cd_s, cp_s, cv_s = cut.s, cut.d, cut.p, cut.v
    n_s = cs_s.shape[0]
    t_end = (n_s - 1) * _DT
    n = round(t_end / h) + 1
    cs = np.empty(n)
    cd = np.empty(n)
    cp = np.empty(n)
    cv = np.empty(n)
    es = np.empty(n)
    ev = np.empty(n)
    ratio = round(_DT / h)
    for i in range(n):
        t = i * h
        es[i] = cut.v_e * t
        ev[i] = cut.v_e
        k = i // ratio
        f = (i - k * ratio) / ratio
        if k >= n_s - 1:
            k = n_s - 2
            f = 1.0
        cs[i] = cs_s[k] * (1.0 - f) + cs_s[k + 1] * f
        cd[i] = cd_s[k] * (1.0 - f) + cd_s[k + 1] * f
        cp[i] = cp_s[k] * (1.0 - f) + cp_s[k + 1] * f
        cv[i] = cv_s[k] * (1.0 - f) + cv_s[k + 1] * f
    return cs, cd, cp, cv, es, ev


@numba.njit(cache=True)
def _first_step(t_p: float, h: float, cd: FloatArray, cp: FloatArray,
                box: _Box) -> int:  # pragma: no cover - jit
    """Where the drivers' runs start on the grid: at t_p or when the cutter first meets
    the ego's band, whichever is earlier (before, all follow the script)."""
    k0 = math.floor(t_p / h)
    radius = math.hypot(box.chl, box.chw)
    for i in range(k0):
        if abs(cd[i]) - radius > box.ehw:  # clear whatever its heading: no trigonometry
            continue
        if not _ck.lateral_clear(cd[i], math.cos(cp[i]), math.sin(cp[i]), box.chl, box.chw,
                                 box.ehw):
            return i
    return k0


@numba.njit(cache=True)
def _drivers_grid(cut: _Cutter, box: _Box, cfg: _Settings
                  ) -> tuple[float, float, float, float, float]:  # pragma: no cover - jit
    """The baseline (the path before the pruned kernels): the samples on the h grid, the
    grid kernels over it. Returns (none contact, its impact speed, R157 contact, its
    impact speed, a_req)."""
    ehl, ehw, chl, chw = box
    h, t_p, t_stop = cfg.h, cut.t_p, cut.t_stop
    cs, cd, cp, cv, es, ev = _on_grid(cut, h)
    k_const = cs.shape[0] - 1
    k0 = _first_step(t_p, h, cd, cp, box)
    t0 = k0 * h
    cs_, cd_, cp_, cv_, es_, ev_ = cs[k0:], cd[k0:], cp[k0:], cv[k0:], es[k0:], ev[k0:]
    kc = k_const - k0
    c_none, imp_none, _ = _ck.drive(t0, h, cs_, cd_, cp_, cv_, es_, ev_, ehl, ehw, chl,
                                    chw, np.nan, cfg.jerk, cfg.a_max, t_p, kc, t_stop)
    t_r = _ck.r157_reaction_start(t0, h, cs_, cp_, cv_, es_, ev_, ehl + chl, t_p,
                                  cfg.ttc_crit, kc, t_stop)
    t_b = t_r + cfg.reaction
    if not math.isnan(c_none) and c_none <= t_b:  # contact before the brakes come on
        c_r, imp_r = c_none, imp_none
    else:
        kb = k0
        if not math.isnan(t_b):
            kb = min(max(math.floor(t_b / h) - 1, k0), k_const)
        c_r, imp_r, _ = _ck.drive(kb * h, h, cs[kb:], cd[kb:], cp[kb:], cv[kb:], es[kb:],
                                  ev[kb:], ehl, ehw, chl, chw, t_b, cfg.jerk, cfg.a_max,
                                  t_p, k_const - kb, t_stop)
    a_req = 0.0
    if not math.isnan(c_none):
        t_b0 = t_p + cfg.reaction
        if c_none <= t_b0:
            a_req = np.inf
        else:
            ka = min(max(math.floor(t_b0 / h) - 1, 0), k_const)
            a_req = _ck.required_decel(ka * h, h, cs[ka:], cd[ka:], cp[ka:], cv[ka:],
                                       es[ka:], ev[ka:], ehl, ehw, chl, chw, t_b0,
                                       k_const - ka)
    return c_none, imp_none, c_r, imp_r, a_req


@numba.njit(cache=True, nogil=True)
def _all(params: FloatArray, lane_width: float, man_a: FloatArray, man_w: FloatArray,
         out: FloatArray, settings: FloatArray) -> None:  # pragma: no cover
    cfg = _Settings(settings[0], settings[1], settings[2], settings[3], settings[4],
                    settings[5], settings[6], settings[7], settings[8], settings[9],
                    settings[10] != 0.0)
    for r in range(params.shape[0]):
        _one(params[r], lane_width, man_a[r], man_w[r], out[r], cfg)


def _ego_speed(params: FloatArray, lane_width: float) -> FloatArray:
    """v_ego of each row (NaN where it has no crossing): for the manoeuvres' inputs."""
    kin = crossing_kinematics(params, lane_width / 2.0)
    return np.asarray(kin.v_cross + params[:, 6], dtype=np.float64)


def _manoeuvre_inputs(arr: FloatArray, lane_width: float, rs: RiskSettings,
                      with_ttr: bool) -> tuple[FloatArray, FloatArray]:
    """The TTR scan's manoeuvres' inputs (acceleration, yaw rate) at each row's ego speed,
    shape (n, len(MANOEUVRES)) each; zeros without the scan."""
    n = arr.shape[0]
    man_a = np.zeros((n, len(MANOEUVRES)))
    man_w = np.zeros((n, len(MANOEUVRES)))
    if with_ttr and n:
        v_e = _ego_speed(arr, lane_width)
        v_safe = np.where(np.isfinite(v_e) & (v_e > 0), v_e, 1.0)
        for k, man in enumerate(MANOEUVRES):
            man_a[:, k], man_w[:, k] = man.inputs(v_safe, rs)
    return man_a, man_w


def criticality_quantities(params: FloatArray, lane_width: float = DEFAULT_LANE_WIDTH, *,
                           settings: CriticalitySettings | None = None,
                           risk_settings: RiskSettings | None = None,
                           with_ttr: bool = True,
                           baseline: bool = False) -> dict[str, FloatArray]:
    """The quantities of :data:`CRITICALITY_QUANTITIES` for rows of parameter vectors.

    Parameters
    ----------
    params : ndarray of shape (n, 8)
        ``PARAM_NAMES`` order, SI units.
    lane_width : float
        Lane width in m.
    settings, risk_settings : optional
        As for :func:`riskcore.criticality.evaluate_criticality` (defaults when None).
        ``settings.step`` must divide the builder's 0.1 s sample step.
    with_ttr : bool
        False: skip the TTR scan (the costliest part); ``ttr_true`` is then NaN.
    baseline : bool
        True: the earlier, slower path (every step of the simulation grid), kept as the
        benchmark's baseline and as a cross-check in the tests; same quantities.

    Returns
    -------
    dict of name -> ndarray of shape (n,)
        NaN where the row is not a buildable cut-in.
    """
    arr = jit.kernel_input(params)  # one compiled version whoever calls
    if arr.ndim != 2 or arr.shape[1] != 8:
        raise SamplerError(f"params: expected shape (n, 8), got {arr.shape}", field="params",
                           problem="wrong shape", value=arr.shape)
    s = settings or CriticalitySettings()
    rs = risk_settings or RiskSettings()
    ratio = round(_DT / s.step)
    if ratio < 1 or abs(ratio * s.step - _DT) > 1e-12:
        raise SamplerError(f"settings.step: must divide {_DT} s for the sampler-level "
                           f"quantities, got {s.step}", field="settings.step",
                           problem="does not divide the sample step", value=s.step)
    man_a, man_w = _manoeuvre_inputs(arr, lane_width, rs, with_ttr)
    out = np.empty((arr.shape[0], len(CRITICALITY_QUANTITIES)))
    vec = np.array([s.wandering_zone, s.reaction_time, s.jerk, s.decel_max, s.critical_ttc,
                    s.step, s.tail, s.follow_horizon, rs.dt,
                    s.ttr_tail if with_ttr else -1.0, 1.0 if baseline else 0.0])
    _all(arr, float(lane_width), man_a, man_w, out, vec)
    return {name: out[:, j].copy() for j, name in enumerate(CRITICALITY_QUANTITIES)}
