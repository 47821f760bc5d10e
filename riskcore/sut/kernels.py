"""Compiled (numba) kernels of the closed-loop simulator: use :func:`simulate`. The vehicle
model and the box geometry are also public on ``riskcore.sut`` (:func:`ego_advance`,
:func:`ego_advance_with_onset`, :func:`band_range`, :func:`box_clearance`): the esmini
adapter (app.esmini) moves its ego and tests contact with them.

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
    # the first root of v + a tau + jj tau^2 / 2 in [0, T] where the speed falls, if any
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
            slope = a + jj * lo
            if 0.0 <= lo <= T and (slope < 0.0 or (slope == 0.0 and jj < 0.0)):
                t_stop = lo  # (not where the speed rises from 0: v = 0, a > 0)
            elif 0.0 <= hi <= T and v_end < 0.0:
                t_stop = hi
        if t_stop < 0.0 and v_end < 0.0:
            # rounding (e.g. a subnormal speed or acceleration) hid the root: the speed
            # starts >= 0 and ends below 0, so it falls through 0 in between; bisect
            lo = 0.0
            hi = T
            for _ in range(_BISECT):
                mid = 0.5 * (lo + hi)
                if v + a * mid + 0.5 * jj * mid * mid < 0.0:
                    hi = mid
                else:
                    lo = mid
            t_stop = lo
    if t_stop >= 0.0:
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
        return x, 0.0, 0.0, a != 0.0  # at standstill: a snaps to 0
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
def ego_advance_with_onset(x: float, v: float, a: float, u_old: float, u: float, d: float,
                           j: float, tau: float
                           ) -> tuple[float, float, float, bool]:  # pragma: no cover - jit
    """:func:`ego_advance` when the command changes from ``u_old`` to ``u`` ``d`` s into
    the step (``d = 0``: ``u`` throughout)."""
    if d <= 0.0:
        return ego_advance(x, v, a, u, j, tau)
    if tau <= d:
        return ego_advance(x, v, a, u_old, j, tau)
    x1, v1, a1, st1 = ego_advance(x, v, a, u_old, j, d)
    x2, v2, a2, st2 = ego_advance(x1, v1, a1, u, j, tau - d)
    return x2, v2, a2, st1 or st2


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
def band_range(x: float, y: float, p: float, hl: float, hw: float,
               band: float) -> tuple[bool, float, float]:  # pragma: no cover - jit
    """The x-range of a box (centre x, y, heading p, half length hl, half width hw) inside
    the band ``|y| <= band``: (it meets the band, x_lo, x_hi); the criticality record's
    geometry (module docstring)."""
    return _ck.band_range(x, y, math.cos(p), math.sin(p), hl, hw, band)


@njit(cache=True)
def box_clearance(x: float, y: float, p: float, xe: float, ehl: float, ehw: float,
                  chl: float, chw: float) -> tuple[bool, float]:  # pragma: no cover - jit
    """The cutter's box (centre x, y, heading p, half sizes chl, chw) against the ego's
    (centre xe, 0, heading 0, half sizes ehl, ehw): (it meets the ego's band beside or
    ahead of the ego, the free distance ahead of the ego's front inside its band; < 0: the
    boxes overlap)."""
    c = math.cos(p)
    sn = math.sin(p)
    if _ck.lateral_clear(y, c, sn, chl, chw, ehw):
        return False, np.nan
    meets, lo, hi = _ck.band_range(x, y, c, sn, chl, chw, ehw)
    if not (meets and hi > xe - ehl):
        return False, np.nan
    return True, lo - (xe + ehl)


@njit(cache=True)
def _overlap_at(tau: float, t0: float, x: float, v: float, a: float, u_old: float, u: float,
                d: float, j: float,
                cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
                ca: FloatArray, i: int, h: float, ehl: float, ehw: float, chl: float,
                chw: float) -> bool:  # pragma: no cover - jit
    xe, _, _, _ = ego_advance_with_onset(x, v, a, u_old, u, d, j, tau)
    px, py, pp, _, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t0 + tau)
    near, gap = box_clearance(px, py, pp, xe, ehl, ehw, chl, chw)
    return near and gap < 0.0


# columns of the per-run outcome array ``out`` (N, N_OUT)
T_CONTACT, IMPACT, MIN_GAP, MIN_TTC, MIN_THW, MAX_DECEL, MAX_JERK, T_BRAKE, END_TIME, \
    INTR_PREV, INTR_T, INTR_TTC, INTR_VREL = range(13)
N_OUT = 13
# entries of the settings array ``prm``
P_DT, P_H, P_JERK, P_EHL, P_EHW, P_INTRUDE, P_TMAX, P_BRAKE, P_RANGE, P_HALF_LANE = range(10)
N_PRM = 10


def new_outcomes(n: int) -> FloatArray:
    """The outcome array of n runs before the first step."""
    out = np.full((n, N_OUT), np.nan)
    out[:, IMPACT] = 0.0
    out[:, MIN_GAP] = np.inf
    out[:, MIN_TTC] = np.inf
    out[:, MIN_THW] = np.inf
    out[:, MAX_DECEL] = 0.0
    out[:, MAX_JERK] = 0.0
    out[:, INTR_PREV] = np.inf
    return out


@njit(cache=True)
def _clearance_cs(x: float, y: float, c: float, sn: float, xe: float, ehl: float,
                  ehw: float, chl: float, chw: float) -> tuple[bool, float]:  # pragma: no cover
    """:func:`box_clearance` with the heading's cos and sin given."""
    if _ck.lateral_clear(y, c, sn, chl, chw, ehw):
        return False, np.nan
    meets, lo, hi = _ck.band_range(x, y, c, sn, chl, chw, ehw)
    if not (meets and hi > xe - ehl):
        return False, np.nan
    return True, lo - (xe + ehl)


@njit(cache=True)
def _intrusion_ttc(gl: float, clos: float) -> float:  # pragma: no cover - jit
    if clos > 0.0:
        return gl / clos if gl > 0.0 else 0.0
    return np.inf


@njit(cache=True)
def start_one(i: int, x: float, v: float, px: float, py: float, c: float, sn: float,
              pv: float, chl: float, chw: float, prm: FloatArray, out: FloatArray,
              code: NDArray[np.int8], collided: NDArray[np.bool_]) -> bool:  # pragma: no cover
    """Run i at time 0 (cutter at px, py, heading cos c / sin sn, speed pv): the
    regulation's intrusion state and a contact already there. True: the run is over."""
    ehl = prm[P_EHL]
    inner = abs(py) - (chl * abs(sn) + chw * abs(c))
    out[i, INTR_PREV] = inner
    if inner <= prm[P_INTRUDE]:
        clos = v - pv * c
        out[i, INTR_T] = 0.0
        out[i, INTR_VREL] = clos
        out[i, INTR_TTC] = _intrusion_ttc(px - x - ehl - chl, clos)
    near, g = _clearance_cs(px, py, c, sn, x, ehl, prm[P_EHW], chl, chw)
    if near and g < 0.0:
        collided[i] = True
        out[i, T_CONTACT] = 0.0
        out[i, IMPACT] = math.hypot(v - pv * c, pv * sn)
        out[i, MIN_GAP] = 0.0
        out[i, END_TIME] = 0.0
        code[i] = CONTACT
        return True
    return False


@njit(cache=True)
def step_one(i: int, k: int, uo: float, ui: float, d: float, x: FloatArray, v: FloatArray,
             a: FloatArray, cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
             ca: FloatArray, chl: float, chw: float, t_p: float, t_end: float,
             prm: FloatArray, out: FloatArray, code: NDArray[np.int8],
             collided: NDArray[np.bool_]
             ) -> tuple[bool, float, float, float, float, float, float, float
                        ]:  # pragma: no cover - jit
    """Advance run i from step k to k + 1 (command ``uo`` until ``d`` s into the step, then
    ``ui``): contact, margins, the regulation's moment and the end of the run.

    Returns (the run is over, and the cutter's x, y, heading, speed, acceleration, cos and
    sin of the heading at the step's end)."""
    dt = prm[P_DT]
    h = prm[P_H]
    j = prm[P_JERK]
    ehl = prm[P_EHL]
    ehw = prm[P_EHW]
    t0 = k * dt
    t1 = (k + 1) * dt  # as the next step's observation time
    if math.isnan(out[i, T_BRAKE]):
        if uo <= -prm[P_BRAKE]:
            out[i, T_BRAKE] = t0
        elif ui <= -prm[P_BRAKE]:
            out[i, T_BRAKE] = t0 + d
    xi = x[i]
    vi = v[i]
    ai = a[i]
    x1, v1, a1, stopped = ego_advance_with_onset(xi, vi, ai, uo, ui, d, j, dt)
    px, py, pp, pv, pa = cutter_at(cx, cy, cpsi, cv, ca, i, h, t1)
    c = math.cos(pp)
    sn = math.sin(pp)
    near, g = _clearance_cs(px, py, c, sn, x1, ehl, ehw, chl, chw)
    if near and g < 0.0:
        lo = 0.0
        hi = dt
        for _ in range(_BISECT):
            mid = 0.5 * (lo + hi)
            if _overlap_at(mid, t0, xi, vi, ai, uo, ui, d, j, cx, cy, cpsi, cv, ca, i, h,
                           ehl, ehw, chl, chw):
                hi = mid
            else:
                lo = mid
        xc, vc_e, ac, _ = ego_advance_with_onset(xi, vi, ai, uo, ui, d, j, hi)
        _, _, qp, qv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t0 + hi)
        collided[i] = True
        out[i, T_CONTACT] = t0 + hi
        out[i, IMPACT] = math.hypot(vc_e - qv * math.cos(qp), qv * math.sin(qp))
        out[i, MIN_GAP] = 0.0
        out[i, MAX_DECEL] = max(out[i, MAX_DECEL], -ac)
        x[i] = xc
        v[i] = vc_e
        a[i] = ac
        out[i, END_TIME] = t0 + hi
        code[i] = CONTACT
        return True, px, py, pp, pv, pa, c, sn
    if not stopped:
        out[i, MAX_JERK] = max(out[i, MAX_JERK], abs(a1 - ai) / dt)
    out[i, MAX_DECEL] = max(out[i, MAX_DECEL], -a1)
    x[i] = x1
    v[i] = v1
    a[i] = a1
    clos = v1 - pv * c
    # the regulation's moment: the cutter 0.3 m into the ego lane (interpolated)
    inner = abs(py) - (chl * abs(sn) + chw * abs(c))
    intrude_at = prm[P_INTRUDE]
    if inner <= intrude_at and math.isnan(out[i, INTR_T]):
        prev = out[i, INTR_PREV]
        f = (prev - intrude_at) / (prev - inner) if prev > inner else 1.0
        out[i, INTR_T] = t0 + f * dt
        out[i, INTR_VREL] = clos
        out[i, INTR_TTC] = _intrusion_ttc(px - x1 - ehl - chl, clos)
    out[i, INTR_PREV] = inner
    if near and (math.isnan(t_p) or t1 >= t_p):
        if g < out[i, MIN_GAP]:
            out[i, MIN_GAP] = g
        if clos > 0.0 and g / clos < out[i, MIN_TTC]:
            out[i, MIN_TTC] = g / clos
        if v1 > 0.0 and g / v1 < out[i, MIN_THW]:
            out[i, MIN_THW] = g / v1
    # the end: the conflict resolved, or the time limit
    end = RUNNING
    if t1 >= t_end - 1e-9:
        straight = abs(sn) < 1e-9
        behind = px + chl < x1 - ehl
        if behind and pv * c <= v1:
            end = LEFT_BEHIND
        elif not near and straight and not behind:
            meets, _, _ = _ck.band_range(px, py, c, sn, chl, chw, ehw)
            if not meets:
                end = NO_CONFLICT
        elif near and straight and clos <= 0.0 and a1 <= SETTLE_ACCEL:
            end = SETTLED
    if end == RUNNING and t1 >= prm[P_TMAX] - 1e-9:
        end = TIME_LIMIT
    if end != RUNNING:
        code[i] = end
        out[i, END_TIME] = t1
        return True, px, py, pp, pv, pa, c, sn
    return False, px, py, pp, pv, pa, c, sn


@njit(cache=True)
def observe(k: int, delay: int, hist: FloatArray, x: FloatArray, v: FloatArray,
            a: FloatArray, active: NDArray[np.bool_], cx: FloatArray, cy: FloatArray,
            cpsi: FloatArray, cv: FloatArray, ca: FloatArray, c_length: FloatArray,
            c_width: FloatArray, prm: FloatArray, o_t: FloatArray, o_v: FloatArray,
            o_a: FloatArray, present: NDArray[np.bool_], dx: FloatArray, gap: FloatArray,
            dy: FloatArray, ov: FloatArray, vx: FloatArray, vy: FloatArray, oa: FloatArray,
            psi: FloatArray, length: FloatArray, width: FloatArray, lane: NDArray[np.int8],
            dy0: FloatArray) -> None:  # pragma: no cover - jit
    """Fill the observation arrays at step k (objects as of ``delay`` steps before)."""
    n = x.shape[0]
    m = hist.shape[1]
    dt = prm[P_DT]
    ehl = prm[P_EHL]
    kd = k - delay
    if kd < 0:
        kd = 0
    t_obs = kd * dt
    for i in range(n):
        o_t[i] = k * dt
        o_v[i] = v[i]
        o_a[i] = a[i]
        xe = hist[i, kd % m] if delay > 0 else x[i]
        px, py, pp, pv, pa = cutter_at(cx, cy, cpsi, cv, ca, i, prm[P_H], t_obs)
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
        lane[i, 0] = 0 if abs(py) <= prm[P_HALF_LANE] else (1 if py > 0.0 else -1)
        dy0[i, 0] = cy[i, 0]
        present[i, 0] = active[i] and d * d + py * py <= prm[P_RANGE] * prm[P_RANGE]


@njit(cache=True)
def advance(k: int, u_old: FloatArray, u: FloatArray, onset: FloatArray, x: FloatArray,
            v: FloatArray, a: FloatArray, active: NDArray[np.bool_], hist: FloatArray,
            cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray, ca: FloatArray,
            c_length: FloatArray, c_width: FloatArray, t_p: FloatArray, t_end: FloatArray,
            prm: FloatArray, out: FloatArray, code: NDArray[np.int8],
            collided: NDArray[np.bool_]) -> int:  # pragma: no cover - jit
    """Advance every active run from step k to k + 1 (:func:`step_one`). Returns the
    number still active."""
    n = x.shape[0]
    m = hist.shape[1]
    left = 0
    for i in range(n):
        if not active[i]:
            continue
        chl = 0.5 * c_length[i]
        chw = 0.5 * c_width[i]
        if k == 0:
            px, py, pp, pv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, prm[P_H], 0.0)
            if start_one(i, x[i], v[i], px, py, math.cos(pp), math.sin(pp), pv, chl, chw,
                         prm, out, code, collided):
                active[i] = False
                continue
        over, _, _, _, _, _, _, _ = step_one(i, k, u_old[i], u[i], onset[i], x, v, a, cx,
                                             cy, cpsi, cv, ca, chl, chw, t_p[i], t_end[i],
                                             prm, out, code, collided)
        hist[i, (k + 1) % m] = x[i]
        if over:
            active[i] = False
        else:
            left += 1
    return left


# --------------------------------------------------------------------------- built-ins
# compiled policies of the built-in SUTs (the same formulas as riskcore.sut.suts)
K_NONE, K_IDM, K_ACC, K_ACC_AEB = range(4)


@njit(cache=True, inline="always")
def _policy(kind: int, q: FloatArray, t: float, ve: float, has: bool, gap: float,
            vl: float, v_des: float, firing: bool) -> tuple[float, bool]:  # pragma: no cover
    """Command of a compiled built-in (``q``: its parameters, see suts.py) and the AEB's
    firing state. Inlined into the step loops (numba's ``inline="always"``): as a call,
    with its arguments and result passed through memory, it took a tenth of the fused
    loop's time."""
    if kind == K_IDM:  # q: a, b, T, s0, delta
        r = ve / v_des
        if q[4] == 4.0:  # the usual exponent: exactly as suts.IDM computes it
            r2 = r * r
            free = 1.0 - r2 * r2
        else:
            free = 1.0 - r ** q[4]
        if not has:
            return q[0] * free, firing
        s = max(gap, 0.01)
        s_star = q[3] + max(0.0, ve * q[2] + ve * (ve - vl) / (2.0 * math.sqrt(q[0] * q[1])))
        return q[0] * (free - (s_star / s) ** 2), firing
    if kind in (K_ACC, K_ACC_AEB):
        # q: k0, k1, k2, time_gap, s0, a_min, a_max, range, ttc, a_aeb
        cruise = q[0] * (v_des - ve)
        cmd = cruise
        if has and gap <= q[7]:
            cmd = min(cruise, q[1] * (gap - q[4] - q[3] * ve) + q[2] * (vl - ve))
        cmd = min(max(cmd, q[5]), q[6])
        if kind == K_ACC_AEB:
            clos = ve - vl
            if has and clos > 0.0 and gap / clos < q[8]:
                firing = True
            if has and not clos > 0.0:
                firing = False
            if firing:
                return -q[9], firing
        return cmd, firing
    return 0.0, firing


@njit(cache=True)
def _grid_weights(n_steps: int, dt: float, h: float,
                  m: int) -> tuple[NDArray[np.int64], FloatArray]:  # pragma: no cover - jit
    """For the end ``t1 = (k + 1) dt`` of each step k, :func:`cutter_at`'s interval of the
    grid (step h, m points) and its weight f on the interval's right end, computed as
    :func:`cutter_at` does (``u = t1 / h``, ``floor``); interval -1: past the grid. The
    same for every run, so :func:`run_builtin` reads them instead of dividing and
    rounding at every step of every run."""
    kk_at = np.empty(n_steps, dtype=np.int64)
    f_at = np.empty(n_steps)
    for k in range(n_steps):
        uu = ((k + 1) * dt) / h
        if uu >= m - 1:
            kk_at[k] = -1
            f_at[k] = np.nan
        else:
            kk = math.floor(uu)
            if kk > m - 2:
                kk = m - 2
            kk_at[k] = kk
            f_at[k] = uu - kk
    return kk_at, f_at


@njit(cache=True)
def run_builtin_stepwise(kind: int, q: FloatArray, v_des: FloatArray, upd: int, n_steps: int,
                a_lo: float, a_hi: float, x: FloatArray, v: FloatArray, a: FloatArray,
                cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
                ca: FloatArray, c_length: FloatArray, c_width: FloatArray, t_p: FloatArray,
                t_end: FloatArray, prm: FloatArray, out: FloatArray, code: NDArray[np.int8],
                collided: NDArray[np.bool_]) -> None:  # pragma: no cover - jit
    """Every run of a compiled built-in SUT to its end, run after run (no perception
    delay): the same steps as :func:`observe`, the SUT's act and :func:`advance`, one
    :func:`step_one` call per step. The previous fast path, kept as the baseline of
    :func:`run_builtin` (``simulate(engine="stepwise")``): the same results, ~6x slower."""
    n = x.shape[0]
    dt = prm[P_DT]
    ehl = prm[P_EHL]
    for i in range(n):
        chl = 0.5 * c_length[i]
        chw = 0.5 * c_width[i]
        px, py, pp, pv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, prm[P_H], 0.0)
        c = math.cos(pp)
        if start_one(i, x[i], v[i], px, py, c, math.sin(pp), pv, chl, chw, prm, out, code,
                     collided):
            continue
        firing = False
        u = 0.0
        for k in range(n_steps):
            if k % upd == 0:
                d = px - x[i]
                has = (abs(py) <= prm[P_HALF_LANE] and d > 0.0
                       and d * d + py * py <= prm[P_RANGE] * prm[P_RANGE])
                cmd, firing = _policy(kind, q, k * dt, v[i], has, d - ehl - chl, pv * c,
                                      v_des[i], firing)
                u = min(max(cmd, a_lo), a_hi)
            over, px, py, pp, pv, _, c, _ = step_one(i, k, u, u, 0.0, x, v, a, cx, cy, cpsi,
                                                     cv, ca, chl, chw, t_p[i], t_end[i],
                                                     prm, out, code, collided)
            if over:
                break


@njit(cache=True)
def run_builtin(kind: int, q: FloatArray, v_des: FloatArray, upd: int, n_steps: int,
                a_lo: float, a_hi: float, x: FloatArray, v: FloatArray, a: FloatArray,
                cx: FloatArray, cy: FloatArray, cpsi: FloatArray, cv: FloatArray,
                ca: FloatArray, c_length: FloatArray, c_width: FloatArray, t_p: FloatArray,
                t_end: FloatArray, prm: FloatArray, out: FloatArray, code: NDArray[np.int8],
                collided: NDArray[np.bool_]) -> None:  # pragma: no cover - jit
    """:func:`run_builtin_stepwise` fused into one loop per run: the same operations in
    the same order (bit-identical results, tested), with the run's state, margins and the
    cutter's row held in local variables instead of passed to :func:`step_one` and
    written to ``out`` at every step, and the cutter's cos / sin recomputed only when its
    interpolated heading changes (it is constant, bit for bit, before and after the lane
    change). Measured ~6x faster (benchmarks/bench_sut.py); dropping cos / sin from the
    stepwise loop alone gained under a tenth, so most of the gain is the per-step call
    with its 20 array arguments and the stores to ``out`` that this loop does not make.

    The cutter's grid interval and weight at each step's end come from a table
    (:func:`_grid_weights`, the same for every run) rather than ``t1 / h`` and ``floor``
    at every step: the division and the rounding delayed the loads of the cutter's row
    that every later test waits for (measured ~1.2x), and the policy is inlined
    (``_policy``: ~1.1x). Same results, bit for bit.
    """
    n = x.shape[0]
    dt = prm[P_DT]
    h = prm[P_H]
    j = prm[P_JERK]
    ehl = prm[P_EHL]
    ehw = prm[P_EHW]
    brake = -prm[P_BRAKE]
    intrude_at = prm[P_INTRUDE]
    half_lane = prm[P_HALF_LANE]
    rng2 = prm[P_RANGE] * prm[P_RANGE]
    t_max = prm[P_TMAX] - 1e-9
    m = cx.shape[1]
    kk_at, f_at = _grid_weights(n_steps, dt, h, m)
    for i in range(n):
        chl = 0.5 * c_length[i]
        chw = 0.5 * c_width[i]
        px, py, pp, pv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, 0.0)
        c = math.cos(pp)
        sn = math.sin(pp)
        if start_one(i, x[i], v[i], px, py, c, sn, pv, chl, chw, prm, out, code, collided):
            continue
        cxi = cx[i]
        cyi = cy[i]
        cpi = cpsi[i]
        cvi = cv[i]
        xi = x[i]
        vi = v[i]
        ai = a[i]
        vd = v_des[i]
        tpi = t_p[i]
        no_tp = math.isnan(tpi)
        te = t_end[i] - 1e-9
        t_brake = np.nan
        max_jerk = 0.0
        max_decel = 0.0
        min_gap = np.inf
        min_ttc = np.inf
        min_thw = np.inf
        intr_prev = out[i, INTR_PREV]
        intr_done = not math.isnan(out[i, INTR_T])
        last_pp = pp
        firing = False
        u = 0.0
        end = RUNNING
        t1 = 0.0
        phase = 0  # k % upd
        for k in range(n_steps):
            if phase == 0:
                d = px - xi
                has = (abs(py) <= half_lane and d > 0.0 and d * d + py * py <= rng2)
                cmd, firing = _policy(kind, q, k * dt, vi, has, d - ehl - chl, pv * c, vd,
                                      firing)
                u = min(max(cmd, a_lo), a_hi)
            phase = phase + 1 if phase + 1 < upd else 0
            t0 = k * dt
            t1 = (k + 1) * dt
            if math.isnan(t_brake) and u <= brake:
                t_brake = t0
            x1, v1, a1, stopped = ego_advance(xi, vi, ai, u, j, dt)
            # the cutter at t1 (cutter_at, inline; its grid index and weight tabulated)
            kk = kk_at[k]
            if kk < 0:
                tau = t1 - (m - 1) * h
                pp = cpi[m - 1]
                pv = cvi[m - 1]
                if pp != last_pp:
                    c = math.cos(pp)
                    sn = math.sin(pp)
                    last_pp = pp
                px = cxi[m - 1] + pv * c * tau
                py = cyi[m - 1] + pv * sn * tau
            else:
                f = f_at[k]
                g = 1.0 - f
                px = cxi[kk] * g + cxi[kk + 1] * f
                py = cyi[kk] * g + cyi[kk + 1] * f
                pp = cpi[kk] * g + cpi[kk + 1] * f
                pv = cvi[kk] * g + cvi[kk + 1] * f
                if pp != last_pp:
                    c = math.cos(pp)
                    sn = math.sin(pp)
                    last_pp = pp
            near, gg = _clearance_cs(px, py, c, sn, x1, ehl, ehw, chl, chw)
            if near and gg < 0.0:
                lo = 0.0
                hi = dt
                for _ in range(_BISECT):
                    mid = 0.5 * (lo + hi)
                    if _overlap_at(mid, t0, xi, vi, ai, u, u, 0.0, j, cx, cy, cpsi, cv, ca,
                                   i, h, ehl, ehw, chl, chw):
                        hi = mid
                    else:
                        lo = mid
                xc, vc_e, ac, _ = ego_advance_with_onset(xi, vi, ai, u, u, 0.0, j, hi)
                _, _, qp, qv, _ = cutter_at(cx, cy, cpsi, cv, ca, i, h, t0 + hi)
                collided[i] = True
                out[i, T_CONTACT] = t0 + hi
                out[i, IMPACT] = math.hypot(vc_e - qv * math.cos(qp), qv * math.sin(qp))
                min_gap = 0.0
                max_decel = max(max_decel, -ac)
                xi = xc
                vi = vc_e
                ai = ac
                t1 = t0 + hi
                end = CONTACT
                break
            if not stopped:
                max_jerk = max(max_jerk, abs(a1 - ai) / dt)
            max_decel = max(max_decel, -a1)
            xi = x1
            vi = v1
            ai = a1
            clos = v1 - pv * c
            inner = abs(py) - (chl * abs(sn) + chw * abs(c))
            if inner <= intrude_at and not intr_done:
                prev = intr_prev
                ff = (prev - intrude_at) / (prev - inner) if prev > inner else 1.0
                out[i, INTR_T] = t0 + ff * dt
                out[i, INTR_VREL] = clos
                out[i, INTR_TTC] = _intrusion_ttc(px - x1 - ehl - chl, clos)
                intr_done = True
            intr_prev = inner
            if near and (no_tp or t1 >= tpi):
                if gg < min_gap:
                    min_gap = gg
                if clos > 0.0 and gg / clos < min_ttc:
                    min_ttc = gg / clos
                if v1 > 0.0 and gg / v1 < min_thw:
                    min_thw = gg / v1
            if t1 >= te:
                straight = abs(sn) < 1e-9
                behind = px + chl < x1 - ehl
                if behind and pv * c <= v1:
                    end = LEFT_BEHIND
                elif not near and straight and not behind:
                    meets, _, _ = _ck.band_range(px, py, c, sn, chl, chw, ehw)
                    if not meets:
                        end = NO_CONFLICT
                elif near and straight and clos <= 0.0 and a1 <= SETTLE_ACCEL:
                    end = SETTLED
            if end == RUNNING and t1 >= t_max:
                end = TIME_LIMIT
            if end != RUNNING:
                break
        x[i] = xi
        v[i] = vi
        a[i] = ai
        out[i, T_BRAKE] = t_brake
        out[i, MAX_JERK] = max_jerk
        out[i, MAX_DECEL] = max_decel
        out[i, MIN_GAP] = min_gap
        out[i, MIN_TTC] = min_ttc
        out[i, MIN_THW] = min_thw
        out[i, INTR_PREV] = intr_prev
        if end != RUNNING:
            code[i] = end
            out[i, END_TIME] = t1
