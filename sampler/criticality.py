"""Criticality straight from parameter vectors: derived quantities for the constraints.

``criticality_quantities(params, lane_width)`` gives, for many cut-in vectors at once, the
values :func:`riskcore.criticality.evaluate_criticality` would give for the scenario that
:func:`sampler.builder.build_scenario` builds from each vector (default lead-in, step and
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
(``datasets.cutin_model``: closed-form heading and speed, positions by the trapezoidal
rule on 0.01 s steps) at the builder's sample times, puts the samples on the same
0.01 s simulation grid the scenario-level code uses (linear between samples), and runs
the same compiled driver kernels (:mod:`riskcore._criticality_kernels`) and riskcore's
TTR scan. A row that is not a buildable cut-in (no crossing, non-positive ego speed, a
negative cutter speed) gives NaN.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from datasets.cutin_model import DEFAULT_LANE_WIDTH
from riskcore import _criticality_kernels as _ck
from riskcore import _kernels
from riskcore.criticality import CriticalitySettings
from riskcore.evasion import MANOEUVRES
from riskcore.settings import RiskSettings
from sampler._exceptions import SamplerError

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

_LEAD_IN = 2.5  # the builder's defaults
_DT = 0.1
_SIZE = (4.5, 1.8)


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


@numba.njit(cache=True)
def _one(row: FloatArray, lane_width: float, man_a1: FloatArray, man_w1: FloatArray,
         out: FloatArray, wz: float, reaction: float, jerk: float, a_max: float,
         ttc_crit: float, h: float, tail: float, follow: float, ttr_dt: float,
         ttr_tail: float) -> None:  # pragma: no cover - jit
    p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap = (row[0], row[1], row[2], row[3], row[4],
                                                  row[5], row[6], row[7])
    for j in range(out.shape[0]):
        out[j] = np.nan
    for j in range(8):
        if not math.isfinite(row[j]):
            return
    if p_t <= 0.0 or p_a3 < 0.0 or p_y1 == 0.0:
        return
    ehl = 0.5 * _SIZE[0]
    ehw = 0.5 * _SIZE[1]
    chl = ehl
    chw = ehw
    pulse_end = p_a2 + p_a3 if p_a3 > 0.0 else 0.0
    t_settle = _LEAD_IN + max(2.0 * p_t, pulse_end, 0.0)
    # integrate on 0.01 s substeps from tau = -lead_in over the lateral motion and beyond:
    # samples every _DT up to t_settle + 0.1, then constant velocity (as the frames do)
    k_set = math.ceil(t_settle / _DT - 1e-9) + 1
    n_s = k_set + 1
    sx = np.empty(n_s)
    sy = np.empty(n_s)
    sp = np.empty(n_s)
    sv = np.empty(n_s)
    # Simpson's rule on each sample step (two halves); the crossing is found on the
    # quarter-step grid by linear interpolation of |y| (the builder: 1 ms, linear)
    hs = _DT / 2.0
    x = 0.0
    y = 0.0
    tau = -_LEAD_IN
    psi, v, _ = _state(p_y1, p_t, p_a1, p_a2, p_a3, p_v0, tau)
    sx[0], sy[0], sp[0], sv[0] = 0.0, 0.0, psi, v
    offset = lane_width / 2.0
    tau_c = np.nan
    x_c = 0.0
    fx0 = v * math.cos(psi)
    fy0 = v * math.sin(psi)
    for k in range(1, n_s):
        for _ in range(2):
            pm, vm, _ = _state(p_y1, p_t, p_a1, p_a2, p_a3, p_v0, tau + 0.5 * hs)
            p1, v1, _ = _state(p_y1, p_t, p_a1, p_a2, p_a3, p_v0, tau + hs)
            fxm = vm * math.cos(pm)
            fym = vm * math.sin(pm)
            fx1 = v1 * math.cos(p1)
            fy1 = v1 * math.sin(p1)
            y_m = y + hs / 24.0 * (5.0 * fy0 + 8.0 * fym - fy1)  # quadratic through 3 pts
            x_m = x + hs / 24.0 * (5.0 * fx0 + 8.0 * fxm - fx1)
            y1 = y + hs / 6.0 * (fy0 + 4.0 * fym + fy1)
            x1 = x + hs / 6.0 * (fx0 + 4.0 * fxm + fx1)
            if math.isnan(tau_c) and tau + hs >= 0.0 and abs(y1) >= offset:
                # refine on the two halves (|y| rises monotonically here)
                if abs(y_m) >= offset:
                    f = (offset - abs(y)) / (abs(y_m) - abs(y)) if abs(y_m) > abs(y) else 0.0
                    tau_c = tau + f * 0.5 * hs
                    x_c = x + f * (x_m - x)
                else:
                    f = (offset - abs(y_m)) / (abs(y1) - abs(y_m))
                    tau_c = tau + 0.5 * hs + f * 0.5 * hs
                    x_c = x_m + f * (x1 - x_m)
                if tau_c > 2.0 * p_t:
                    tau_c = np.nan
            x, y, tau, psi, v = x1, y1, tau + hs, p1, v1
            fx0, fy0 = fx1, fy1
            if v < 0.0 or vm < 0.0:
                return
        sx[k], sy[k], sp[k], sv[k] = x, y, psi, v
    if math.isnan(tau_c):
        return
    _, v_cut_c, _ = _state(p_y1, p_t, p_a1, p_a2, p_a3, p_v0, tau_c)
    v_e = v_cut_c + dv
    if not v_e > 0.0:
        return
    t_c = _LEAD_IN + tau_c
    x_cut0 = gap + 2.0 * ehl + v_e * t_c - x_c  # x_rel was integrated from tau = -lead_in
    y_start = -lane_width if p_y1 > 0.0 else lane_width
    # the x integral starts at tau = -lead_in, the builder's at tau = 0: only differences
    # matter (x_cut0 is chosen from the same integral at the crossing)
    t_end = (n_s - 1) * _DT
    # the grid runs to the last sample; after it everything is straight at constant
    # speed and the kernels finish in closed form (k_const)
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
        es[i] = v_e * t
        ev[i] = v_e
        k = i // ratio
        f = (i - k * ratio) / ratio
        if k >= n_s - 1:
            k = n_s - 2
            f = 1.0
        cs[i] = x_cut0 + sx[k] * (1.0 - f) + sx[k + 1] * f
        cd[i] = y_start + sy[k] * (1.0 - f) + sy[k + 1] * f
        cp[i] = sp[k] * (1.0 - f) + sp[k + 1] * f
        cv[i] = sv[k] * (1.0 - f) + sv[k + 1] * f
    k_const = n - 1
    vx_end = sv[n_s - 1] * math.cos(sp[n_s - 1])
    # the scenario-level frames simulate tail + (time to close the gap, at most follow)
    gap_end = x_cut0 + sx[n_s - 1] - v_e * t_end - 2.0 * ehl
    closing = v_e - vx_end
    extra = gap_end / closing if closing > 0.0 and gap_end > 0.0 else 0.0
    t_stop = t_end + tail + min(extra, follow)
    # perception moment: the centre has moved wz towards the ego lane (samples, linear)
    t_p = np.nan
    for k in range(1, n_s):
        if abs(sy[k]) >= wz:
            t_p = (k - 1) * _DT + (wz - abs(sy[k - 1])) / (abs(sy[k]) - abs(sy[k - 1])) * _DT
            break
    if math.isnan(t_p):
        return
    out[0] = t_p
    # the drivers' runs start where something can happen: at t_p or when the cutter
    # first meets the ego's band, whichever is earlier (before, all follow the script)
    k0 = math.floor(t_p / h)
    radius = math.hypot(chl, chw)
    for i in range(k0):
        if abs(cd[i]) - radius > ehw:  # clear whatever its heading: no trigonometry
            continue
        if not _ck._lateral_clear(cd[i], math.cos(cp[i]), math.sin(cp[i]), chl, chw, ehw):
            k0 = i
            break
    t0 = k0 * h
    cs_, cd_, cp_, cv_, es_, ev_ = cs[k0:], cd[k0:], cp[k0:], cv[k0:], es[k0:], ev[k0:]
    kc = k_const - k0
    c_none, imp_none, _ = _ck.drive(t0, h, cs_, cd_, cp_, cv_, es_, ev_, ehl, ehw, chl,
                                    chw, np.nan, jerk, a_max, t_p, kc, t_stop)
    t_r = _ck.r157_reaction_start(t0, h, cs_, cp_, cv_, es_, ev_, ehl + chl, t_p, ttc_crit,
                                  kc, t_stop)
    t_b = t_r + reaction
    if not math.isnan(c_none) and c_none <= t_b:  # contact before the brakes come on
        c_r, imp_r = c_none, imp_none
    else:
        # until t_b the R157 ego is the scripted one, which has no contact before c_none:
        # start its run at the step before t_b
        kb = k0
        if not math.isnan(t_b):
            kb = min(max(math.floor(t_b / h) - 1, k0), k_const)
        c_r, imp_r, _ = _ck.drive(kb * h, h, cs[kb:], cd[kb:], cp[kb:], cv[kb:], es[kb:],
                                  ev[kb:], ehl, ehw, chl, chw, t_b, jerk, a_max, t_p,
                                  k_const - kb, t_stop)
    out[4] = 0.0 if math.isnan(c_r) else 1.0
    out[5] = imp_r
    out[6] = 0.0 if math.isnan(c_none) else 1.0
    if math.isnan(c_none):
        out[1] = 0.0
        out[2] = 0.0
        out[3] = np.inf
        return
    t_b0 = t_p + reaction
    if c_none <= t_b0:
        a_req = np.inf
    else:
        ka = min(max(math.floor(t_b0 / h) - 1, 0), k_const)
        a_req = _ck.required_decel(ka * h, h, cs[ka:], cd[ka:], cp[ka:], cv[ka:], es[ka:],
                                   ev[ka:], ehl, ehw, chl, chw, t_b0, k_const - ka)
    out[1] = a_req
    out[2] = a_req / a_max
    if ttr_tail < 0.0:  # the TTR scan is not wanted
        return
    # riskcore's TTR scan at t_p against the actual path (ego frame = road frame here)
    n_t = math.ceil((c_none - t_p) / ttr_dt - 1e-9) + math.ceil(ttr_tail / ttr_dt)
    n_t = max(1, min(n_t, 1000))
    poses = np.zeros((n_t + 1, 4))
    vv = np.full(n_t + 1, v_e)
    traj = np.empty((1, n_t + 1, 4))
    for i in range(n_t + 1):
        tq = t_p + i * ttr_dt
        poses[i, 0] = v_e * tq
        poses[i, 2] = 1.0
        if tq > t_end:  # straight at constant speed after the last sample
            traj[0, i, 0] = cs[n - 1] + vx_end * (tq - t_end)
            traj[0, i, 1] = cd[n - 1]
            pq = cp[n - 1]
        else:
            traj[0, i, 0] = _ck._interp(cs, 0.0, h, tq)
            traj[0, i, 1] = _ck._interp(cd, 0.0, h, tq)
            pq = _ck._interp(cp, 0.0, h, tq)
        traj[0, i, 2] = math.cos(pq)
        traj[0, i, 3] = math.sin(pq)
    n_man = man_a1.shape[0]
    man_a = np.empty((n_t, n_man))
    man_w = np.empty((n_t, n_man))
    for i in range(n_t):
        for m in range(n_man):
            man_a[i, m] = man_a1[m]
            man_w[i, m] = man_w1[m]
    eva = np.empty((n_t, n_man, n_t + 1, 4))
    done = np.zeros((n_t, n_man), dtype=np.bool_)
    first, react, _ = _kernels.ttr_scan(traj, chl, chw, poses, vv, ehl, ehw, man_a, man_w,
                                        ttr_dt, eva, done)
    if first[0] < 0:
        out[3] = np.inf
    elif react[0] < 0:
        out[3] = 0.0
    else:
        out[3] = react[0] * ttr_dt


@numba.njit(cache=True, nogil=True)
def _all(params: FloatArray, lane_width: float, man_a: FloatArray, man_w: FloatArray,
         out: FloatArray, settings: FloatArray) -> None:  # pragma: no cover
    wz, reaction, jerk, a_max, ttc_crit, h, tail, follow, ttr_dt, ttr_tail = (
        settings[0], settings[1], settings[2], settings[3], settings[4], settings[5],
        settings[6], settings[7], settings[8], settings[9])
    for r in range(params.shape[0]):
        _one(params[r], lane_width, man_a[r], man_w[r], out[r], wz, reaction, jerk, a_max,
             ttc_crit, h, tail, follow, ttr_dt, ttr_tail)


def _ego_speed(params: FloatArray, lane_width: float) -> FloatArray:
    """v_ego of each row (NaN where it has no crossing): for the manoeuvres' inputs."""
    from sampler.kinematics import crossing_kinematics

    kin = crossing_kinematics(params, lane_width / 2.0)
    return np.asarray(kin.v_cross + params[:, 6], dtype=np.float64)


def criticality_quantities(params: FloatArray, lane_width: float = DEFAULT_LANE_WIDTH, *,
                           settings: CriticalitySettings | None = None,
                           risk_settings: RiskSettings | None = None,
                           with_ttr: bool = True) -> dict[str, FloatArray]:
    """The quantities of :data:`CRITICALITY_QUANTITIES` for rows of parameter vectors.

    Parameters
    ----------
    params : ndarray of shape (n, 8)
        ``PARAM_NAMES`` order, SI units.
    lane_width : float
        Lane width in m.
    settings, risk_settings : optional
        As for :func:`riskcore.criticality.evaluate_criticality` (defaults when None).
    with_ttr : bool
        False: skip the TTR scan (the costliest part); ``ttr_true`` is then NaN.

    Returns
    -------
    dict of name -> ndarray of shape (n,)
        NaN where the row is not a buildable cut-in.
    """
    arr = np.ascontiguousarray(params, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 8:
        raise SamplerError(f"params: expected shape (n, 8), got {arr.shape}", field="params",
                           problem="wrong shape", value=arr.shape)
    s = settings or CriticalitySettings()
    rs = risk_settings or RiskSettings()
    n = arr.shape[0]
    v_e = _ego_speed(arr, lane_width) if n else np.zeros(0)
    v_safe = np.where(np.isfinite(v_e) & (v_e > 0), v_e, 1.0)
    man_a = np.empty((n, len(MANOEUVRES)))
    man_w = np.empty((n, len(MANOEUVRES)))
    for k, man in enumerate(MANOEUVRES):
        man_a[:, k], man_w[:, k] = man.inputs(v_safe, rs)
    out = np.empty((n, len(CRITICALITY_QUANTITIES)))
    vec = np.array([s.wandering_zone, s.reaction_time, s.jerk, s.decel_max, s.critical_ttc,
                    s.step, s.tail, s.follow_horizon, rs.dt,
                    s.ttr_tail if with_ttr else -1.0])
    _all(arr, float(lane_width), man_a, man_w, out, vec)
    return {name: out[:, j].copy() for j, name in enumerate(CRITICALITY_QUANTITIES)}
