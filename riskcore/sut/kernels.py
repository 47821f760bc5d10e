"""Compiled (numba) kernels of the closed-loop simulator. Private: use :func:`simulate`.

Road frame = the ego's frame: the ego drives along +x at y = 0, heading 0; its box is
``[x - L_e/2, x + L_e/2] x [-W_e/2, W_e/2]``. The cutter's box (centre, heading) is
interpolated linearly on the batch's grid and continued straight at constant speed after
it. Contact, clearance and band geometry are the criticality record's
(:func:`riskcore.criticality.kernels.band_range`): the boxes overlap exactly when the
cutter's x-range inside the ego's band ``|y| <= W_e/2`` reaches behind the ego's front and
ahead of its rear.

The ego's longitudinal dynamics over one step of length ``dt`` with the command ``u``
(clipped to the limits): its acceleration moves towards ``u`` at the jerk limit ``j``,
then stays at ``u``::

    a(tau) = a0 + s j tau  (tau < |u - a0| / j, s = sign(u - a0)),   then a = u
    v(tau) = v0 + int a,   x(tau) = x0 + int v

integrated in closed form; it never reverses: when v reaches 0 while decelerating it
stays at v = 0 with a = 0 until a positive command (the snap of a to 0 at standstill is
not counted as jerk).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from riskcore import jit
from riskcore.criticality import kernels as _ck

jit.register(__file__)  # before the first @njit

FloatArray = NDArray[np.float64]

_BISECT = 52

# end codes of a run
RUNNING = 0
CONTACT = 1
SETTLED = 2
LEFT_BEHIND = 3
NO_CONFLICT = 4
TIME_LIMIT = 5
END_NAMES = ("running", "contact", "settled", "left_behind", "no_conflict", "t_max")
#: "settled": the gap is not shrinking and the ego accelerates by at most this, m/s²
SETTLE_ACCEL = 0.1


@njit(cache=True)
def _piece(x: float, v: float, a: float, jj: float,
           T: float) -> tuple[float, float, float, bool]:  # pragma: no cover - jit
    """Constant jerk jj for T s from (x, v, a); stops (v = 0, a = 0) at the first time v
    falls to 0. Returns (x, v, a, stopped)."""
    if T <= 0.0:
        return x, v, a, False
    v_end = v + a * T + 0.5 * jj * T * T
    # the first root of v + a tau + jj tau^2 / 2 in (0, T], if v goes negative there
    t_stop = -1.0
    if jj == 0.0:
        if a < 0.0 and v + a * T < 0.0:
            t_stop = -v / a
    else:
        disc = a * a - 2.0 * jj * v
        if disc >= 0.0:
            sq = math.sqrt(disc)
            r1 = (-a - sq) / jj
            r2 = (-a + sq) / jj
            lo = min(r1, r2)
            hi = max(r1, r2)
            if 0.0 <= lo <= T:
                t_stop = lo
            elif 0.0 <= hi <= T and v_end < 0.0:
                t_stop = hi
        if t_stop < 0.0 and v_end < 0.0:
            t_stop = T
    if t_stop >= 0.0 and (v > 0.0 or a < 0.0):
        tt = t_stop
        xs = x + v * tt + 0.5 * a * tt * tt + jj * tt * tt * tt / 6.0
        return xs, 0.0, 0.0, True
    return (x + v * T + 0.5 * a * T * T + jj * T * T * T / 6.0, max(v_end, 0.0),
            a + jj * T, False)


@njit(cache=True)
def ego_advance(x: float, v: float, a: float, u: float, j: float,
                tau: float) -> tuple[float, float, float, bool]:  # pragma: no cover - jit
    """The ego's state tau s after (x, v, a) under the command u (module docstring).
    Returns (x, v, a, stopped within tau)."""
    if v <= 0.0 and u <= 0.0 and a <= 0.0:
        return x, 0.0, 0.0, False
    d = u - a
    t1 = abs(d) / j
    s = 1.0 if d > 0.0 else -1.0
    if d == 0.0:
        return _piece(x, v, a, 0.0, tau)
    if t1 >= tau:
        return _piece(x, v, a, s * j, tau)
    x1, v1, a1, st = _piece(x, v, a, s * j, t1)
    if st:
        return x1, v1, a1, True
    return _piece(x1, v1, u, 0.0, tau - t1)


@njit(cache=True)
def cutter_at(cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
              ca: FloatArray, i: int, h: float,
              t: float) -> tuple[float, float, float, float, float]:  # pragma: no cover
    """Cutter i at time t: (x, y, psi, v, a); straight at constant speed past the grid."""
    n = cx.shape[1]
    u = t / h
    if u <= 0.0:
        return cx[i, 0], cy[i, 0], cpsi[i, 0], cv[i, 0], ca[i, 0]
    if u >= n - 1:
        tau = t - (n - 1) * h
        p = cpsi[i, n - 1]
        vv = cv[i, n - 1]
        return (cx[i, n - 1] + vv * math.cos(p) * tau, cy[i, n - 1] + vv * math.sin(p) * tau,
                p, vv, 0.0)
    k = math.floor(u)
    if k > n - 2:
        k = n - 2
    f = u - k
    g = 1.0 - f
    return (cx[i, k] * g + cx[i, k + 1] * f, cy[i, k] * g + cy[i, k + 1] * f,
            cpsi[i, k] * g + cpsi[i, k + 1] * f, cv[i, k] * g + cv[i, k + 1] * f,
            ca[i, k] * g + ca[i, k + 1] * f)


@njit(cache=True)
def clearance(x: float, y: float, p: float, xe: float, ehl: float, ehw: float, chl: float,
              chw: float) -> tuple[bool, float]:  # pragma: no cover - jit
    """(the cutter's box meets the ego's band beside or ahead of the ego, the free distance
    ahead of the ego's front inside its band; < 0: the boxes overlap)."""
    c = math.cos(p)
    sn = math.sin(p)
    if _ck.lateral_clear(y, c, sn, chl, chw, ehw):
        return False, np.nan
    meets, lo, hi = _ck.band_range(x, y, c, sn, chl, chw, ehw)
    if not (meets and hi > xe - ehl):
        return False, np.nan
    return True, lo - (xe + ehl)


@njit(cache=True)
def _overlap_at(tau: float, t0: float, x: float, v: float, a: float, u: float, j: float,
                cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
                ca: FloatArray, i: int, h: float, ehl: float, ehw: float, chl: float,
                chw: float) -> bool:  # pragma: no cover - jit
    xe, _, _, _ = ego_advance(x, v, a, u, j, tau)
    px, py, pp, _, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t0 + tau)
    near, gap = clearance(px, py, pp, xe, ehl, ehw, chl, chw)
    return near and gap < 0.0


@njit(cache=True)
def observe(k: int, dt: float, delay: int, h: float, hist: FloatArray, x: FloatArray,
            v: FloatArray, a: FloatArray, active: NDArray[np.bool_], cx: FloatArray,
            cy: FloatArray, cpsi: FloatArray, cv: FloatArray, ca: FloatArray,
            c_length: FloatArray, c_width: FloatArray, ehl: float, half_lane: float,
            sensor_range: float, o_t: FloatArray, o_v: FloatArray, o_a: FloatArray,
            present: NDArray[np.bool_], dx: FloatArray, gap: FloatArray, dy: FloatArray,
            ov: FloatArray, vx: FloatArray, vy: FloatArray, oa: FloatArray, psi: FloatArray,
            length: FloatArray, width: FloatArray, lane: NDArray[np.int8],
            dy0: FloatArray) -> None:  # pragma: no cover - jit
    """Fill the observation arrays at step k (objects as of ``delay`` steps before)."""
    n = x.shape[0]
    m = hist.shape[1]
    kd = k - delay
    if kd < 0:
        kd = 0
    t_obs = kd * dt
    for i in range(n):
        o_t[i] = k * dt
        o_v[i] = v[i]
        o_a[i] = a[i]
        xe = hist[i, kd % m] if delay > 0 else x[i]
        px, py, pp, pv, pa = cutter_at(cx, cy, cpsi, cv, ca, i, h, t_obs)
        d = px - xe
        dx[i, 0] = d
        gap[i, 0] = d - ehl - 0.5 * c_length[i]
        dy[i, 0] = py
        ov[i, 0] = pv
        vx[i, 0] = pv * math.cos(pp)
        vy[i, 0] = pv * math.sin(pp)
        oa[i, 0] = pa
        psi[i, 0] = pp
        length[i, 0] = c_length[i]
        width[i, 0] = c_width[i]
        lane[i, 0] = 0 if abs(py) <= half_lane else (1 if py > 0.0 else -1)
        dy0[i, 0] = cy[i, 0]
        present[i, 0] = active[i] and math.hypot(d, py) <= sensor_range


@njit(cache=True)
def advance(k: int, dt: float, h: float, j: float, u: FloatArray, x: FloatArray,
            v: FloatArray, a: FloatArray, active: NDArray[np.bool_], hist: FloatArray,
            cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray, ca: FloatArray,
            c_length: FloatArray, c_width: FloatArray, ehl: float, ehw: float,
            t_p: FloatArray, t_end: FloatArray, intrude_at: float, t_max: float,
            brake_threshold: float, collided: NDArray[np.bool_], t_contact: FloatArray,
            impact: FloatArray, min_gap: FloatArray, min_ttc: FloatArray,
            min_thw: FloatArray, max_decel: FloatArray, max_jerk: FloatArray,
            t_brake: FloatArray, end_time: FloatArray, end_code: NDArray[np.int8],
            intr_prev: FloatArray, intr_t: FloatArray, intr_ttc: FloatArray,
            intr_vrel: FloatArray) -> int:  # pragma: no cover - jit
    """Advance every active run from step k to k + 1 under the commands u (clipped by the
    caller); contact, margins and the end of the run. Returns the number still active."""
    n = x.shape[0]
    t0 = k * dt
    t1 = t0 + dt
    m = hist.shape[1]
    left = 0
    for i in range(n):
        if not active[i]:
            continue
        chl = 0.5 * c_length[i]
        chw = 0.5 * c_width[i]
        if k == 0:
            px, py, pp, pv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, 0.0)
            near, g = clearance(px, py, pp, x[i], ehl, ehw, chl, chw)
            inner = abs(py) - (chl * abs(math.sin(pp)) + chw * abs(math.cos(pp)))
            intr_prev[i] = inner
            if inner <= intrude_at:
                intr_t[i] = 0.0
                clos = v[i] - pv * math.cos(pp)
                gl = px - x[i] - ehl - chl
                intr_vrel[i] = clos
                intr_ttc[i] = gl / clos if clos > 0.0 and gl > 0.0 else (
                    0.0 if gl <= 0.0 and clos > 0.0 else np.inf)
            if near and g < 0.0:
                collided[i] = True
                t_contact[i] = 0.0
                impact[i] = math.hypot(v[i] - pv * math.cos(pp), pv * math.sin(pp))
                min_gap[i] = 0.0
                end_time[i] = 0.0
                end_code[i] = CONTACT
                active[i] = False
                continue
        ui = u[i]
        if ui <= -brake_threshold and math.isnan(t_brake[i]):
            t_brake[i] = t0
        x1, v1, a1, stopped = ego_advance(x[i], v[i], a[i], ui, j, dt)
        px, py, pp, pv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t1)
        near, g = clearance(px, py, pp, x1, ehl, ehw, chl, chw)
        if near and g < 0.0:
            lo = 0.0
            hi = dt
            for _ in range(_BISECT):
                mid = 0.5 * (lo + hi)
                if _overlap_at(mid, t0, x[i], v[i], a[i], ui, j, cx, cy, cpsi, cv, ca, i, h,
                               ehl, ehw, chl, chw):
                    hi = mid
                else:
                    lo = mid
            xc, vc_e, ac, _ = ego_advance(x[i], v[i], a[i], ui, j, hi)
            _, _, qp, qv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t0 + hi)
            collided[i] = True
            t_contact[i] = t0 + hi
            impact[i] = math.hypot(vc_e - qv * math.cos(qp), qv * math.sin(qp))
            min_gap[i] = 0.0
            max_decel[i] = max(max_decel[i], -ac)
            x[i] = xc
            v[i] = vc_e
            a[i] = ac
            end_time[i] = t0 + hi
            end_code[i] = CONTACT
            active[i] = False
            continue
        if not stopped:
            max_jerk[i] = max(max_jerk[i], abs(a1 - a[i]) / dt)
        max_decel[i] = max(max_decel[i], -a1)
        x[i] = x1
        v[i] = v1
        a[i] = a1
        hist[i, (k + 1) % m] = x1
        clos = v1 - pv * math.cos(pp)
        # the regulation's moment: the cutter 0.3 m into the ego lane (interpolated)
        inner = abs(py) - (chl * abs(math.sin(pp)) + chw * abs(math.cos(pp)))
        if math.isnan(intr_t[i]) and inner <= intrude_at:
            prev = intr_prev[i]
            f = (prev - intrude_at) / (prev - inner) if prev > inner else 1.0
            intr_t[i] = t0 + f * dt
            gl = px - x1 - ehl - chl
            intr_vrel[i] = clos
            intr_ttc[i] = gl / clos if clos > 0.0 and gl > 0.0 else (
                0.0 if gl <= 0.0 and clos > 0.0 else np.inf)
        intr_prev[i] = inner
        if near and (math.isnan(t_p[i]) or t1 >= t_p[i]):
            if g < min_gap[i]:
                min_gap[i] = g
            if clos > 0.0 and g / clos < min_ttc[i]:
                min_ttc[i] = g / clos
            if v1 > 0.0 and g / v1 < min_thw[i]:
                min_thw[i] = g / v1
        # the end: the conflict resolved, or the time limit
        code = RUNNING
        if t1 >= t_end[i] - 1e-9:
            straight = abs(math.sin(pp)) < 1e-9
            behind = px + chl < x1 - ehl
            if behind and pv * math.cos(pp) <= v1:
                code = LEFT_BEHIND
            elif not near and straight and not behind:
                meets, _, _ = _ck.band_range(px, py, math.cos(pp), math.sin(pp), chl, chw,
                                             ehw)
                if not meets:
                    code = NO_CONFLICT
            elif near and straight and clos <= 0.0 and a1 <= SETTLE_ACCEL:
                code = SETTLED
        if code == RUNNING and t1 >= t_max - 1e-9:
            code = TIME_LIMIT
        if code != RUNNING:
            end_code[i] = code
            end_time[i] = t1
            active[i] = False
        else:
            left += 1
    return left
