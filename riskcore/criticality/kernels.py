"""Compiled (numba) kernels of :mod:`riskcore.criticality`. Private: use the public module.

Everything here works in the *ego frame*: the ego moves along its own path, its box is
axis-aligned at lateral offset 0, heading 0, and its centre is at arc length ``s`` along
the path. The cutter is given on a uniform time grid ``t_k = t0 + k h`` by its centre's
arc length ``cs`` and lateral offset ``cd`` relative to the ego's path, and its heading
``cpsi`` relative to the ego's heading (rad), speed ``cv`` (m/s). For a generated cut-in
(ego at y = 0, heading 0) the ego frame is the road frame.

The ego's box spans ``[s - L_e/2, s + L_e/2] x [-W_e/2, W_e/2]``. The cutter's box meets
the ego's lateral band ``|y| <= W_e/2`` in a convex set whose x-range ``[x_lo, x_hi]``
:func:`band_range` returns exactly (the clip of the four edges against the band); the
boxes overlap exactly when ``x_lo < s + L_e/2`` and ``x_hi > s - L_e/2``. The *clearance*
``x_lo - (s + L_e/2)`` is the free longitudinal distance ahead of the ego's front inside
its band (the gap of a car-following situation).

The ego's longitudinal responses (no lateral reaction):

* scripted: ``es[k]``, ``ev[k]`` (the recorded or generated motion, "none" driver);
* braking from ``t_b`` (state ``s_b, v_b`` taken from the scripted motion there): jerk
  ``j`` until the deceleration reaches ``A``, then ``A`` until standstill::

      tau <= T1 = A / j:   v = v_b - j tau^2 / 2,   s = s_b + v_b tau - j tau^3 / 6
      tau >  T1:           v = v1 - A (tau - T1),   s = s1 + v1 (tau - T1) - A (tau - T1)^2 / 2

  (v1, s1 at tau = T1), stopping where v reaches 0 (in the ramp at tau = sqrt(2 v_b / j)).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from riskcore import jit
from riskcore import kernels as _kernels

jit.register(__file__)  # before the first @njit: one cache per version of the kernels

FloatArray = NDArray[np.float64]

_BISECT = 48  # bisection steps: h / 2**48 < 1e-15 s for h = 0.01 s


@njit(cache=True)
def band_range(cs: float, cd: float, c: float, s: float, hl: float, hw: float,
               band: float) -> tuple[bool, float, float]:  # pragma: no cover - jit
    """x-range of the cutter's box inside the band ``|y| <= band``.

    Box: centre (cs, cd), heading (cos c, sin s), half length hl, half width hw.
    Returns (meets the band, x_lo, x_hi); x_lo = +inf, x_hi = -inf when it does not.
    """
    ux, uy = hl * c, hl * s
    nx, ny = -hw * s, hw * c
    px = (cs + ux + nx, cs - ux + nx, cs - ux - nx, cs + ux - nx)
    py = (cd + uy + ny, cd - uy + ny, cd - uy - ny, cd + uy - ny)
    lo = np.inf
    hi = -np.inf
    for e in range(4):
        x0 = px[e]
        y0 = py[e]
        x1 = px[(e + 1) % 4]
        y1 = py[(e + 1) % 4]
        dy = y1 - y0
        if dy == 0.0:
            if abs(y0) > band:
                continue
            a, b = 0.0, 1.0
        else:
            t1 = (-band - y0) / dy
            t2 = (band - y0) / dy
            if t1 > t2:
                t1, t2 = t2, t1
            a = max(t1, 0.0)
            b = min(t2, 1.0)
            if a > b:
                continue
        xa = x0 + a * (x1 - x0)
        xb = x0 + b * (x1 - x0)
        lo = min(lo, xa, xb)
        hi = max(hi, xa, xb)
    return lo <= hi, lo, hi


@njit(cache=True)
def brake_state(v_b: float, jerk: float, a_max: float,
                tau: float) -> tuple[float, float]:  # pragma: no cover - jit
    """Distance travelled and speed ``tau`` s after braking starts at speed ``v_b``.

    Jerk-limited ramp to ``a_max`` then constant deceleration until standstill (see the
    module docstring). ``jerk = inf`` is an instant step to ``a_max``.
    """
    if tau <= 0.0:
        return 0.0, v_b
    if v_b <= 0.0:
        return 0.0, 0.0
    t1 = a_max / jerk if jerk < np.inf else 0.0
    t_ramp_stop = math.sqrt(2.0 * v_b / jerk) if jerk < np.inf else 0.0
    if jerk < np.inf and t_ramp_stop <= t1:  # stops within the ramp
        tt = min(tau, t_ramp_stop)
        return v_b * tt - jerk * tt ** 3 / 6.0, max(v_b - 0.5 * jerk * tt * tt, 0.0)
    if tau <= t1:
        return v_b * tau - jerk * tau ** 3 / 6.0, v_b - 0.5 * jerk * tau * tau
    v1 = v_b - 0.5 * jerk * t1 * t1 if t1 > 0.0 else v_b
    s1 = v_b * t1 - jerk * t1 ** 3 / 6.0 if t1 > 0.0 else 0.0
    tt = min(tau - t1, v1 / a_max)
    return s1 + v1 * tt - 0.5 * a_max * tt * tt, max(v1 - a_max * tt, 0.0)


@njit(cache=True)
def brake_time_to(v_b: float, jerk: float, a_max: float,
                  v: float) -> float:  # pragma: no cover - jit
    """Time after braking starts (see :func:`brake_state`) at which the speed has fallen
    from ``v_b`` to ``max(v, 0)`` (0 when it is there already)."""
    v = max(v, 0.0)
    if v >= v_b:
        return 0.0
    if jerk == np.inf:
        return (v_b - v) / a_max
    t1 = a_max / jerk
    v1 = v_b - 0.5 * jerk * t1 * t1
    if v >= v1:  # within the ramp (also when it stops within the ramp)
        return math.sqrt(2.0 * (v_b - v) / jerk)
    return t1 + (v1 - v) / a_max


@njit(cache=True)
def interp(arr: FloatArray, t0: float, h: float, t: float) -> float:  # pragma: no cover
    """Linear interpolation of a grid array at time t (clamped to the grid)."""
    n = arr.shape[0]
    u = (t - t0) / h
    if u <= 0.0:
        return arr[0]
    if u >= n - 1:
        return arr[n - 1]
    k = math.floor(u)
    f = u - k
    return arr[k] * (1.0 - f) + arr[k + 1] * f


@njit(cache=True)
def _ego_scripted(es: FloatArray, ev: FloatArray, t0: float, h: float,
                  t: float) -> tuple[float, float]:  # pragma: no cover - jit
    """Scripted ego: interpolated on the grid, at its last speed after the grid's end."""
    t_last = t0 + (es.shape[0] - 1) * h
    if t > t_last:
        return es[es.shape[0] - 1] + ev[ev.shape[0] - 1] * (t - t_last), ev[ev.shape[0] - 1]
    return interp(es, t0, h, t), interp(ev, t0, h, t)


@njit(cache=True)
def ego_at(t: float, t0: float, h: float, es: FloatArray, ev: FloatArray, t_b: float,
           jerk: float, a_max: float) -> tuple[float, float]:  # pragma: no cover - jit
    """Ego arc length and speed at time t: scripted before ``t_b`` (NaN: never), braking
    from the scripted state at ``t_b`` afterwards."""
    if not (t > t_b):  # also when t_b is NaN
        return _ego_scripted(es, ev, t0, h, t)
    s_b, v_b = _ego_scripted(es, ev, t0, h, t_b)
    ds, v = brake_state(v_b, jerk, a_max, t - t_b)
    return s_b + ds, v


@njit(cache=True)
def _cutter_at(t: float, t0: float, h: float, cs: FloatArray, cd: FloatArray,
               cpsi: FloatArray, cv: FloatArray
               ) -> tuple[float, float, float, float]:  # pragma: no cover - jit
    return (interp(cs, t0, h, t), interp(cd, t0, h, t), interp(cpsi, t0, h, t),
            interp(cv, t0, h, t))


@njit(cache=True)
def lateral_clear(cd: float, c: float, s: float, chl: float, chw: float,
                   ehw: float) -> bool:  # pragma: no cover - jit
    """Cheap test: the cutter's box lies entirely outside the ego's band |y| <= ehw."""
    return abs(cd) - (chl * abs(s) + chw * abs(c)) > ehw


@njit(cache=True)
def _clearance(x: float, y: float, p: float, s: float, ehl: float, ehw: float, chl: float,
               chw: float) -> tuple[bool, float, float, float]:  # pragma: no cover - jit
    """The cutter's box (centre x, y, heading p) against the ego's at arc length s:
    (it meets the ego's band beside or ahead of the ego, the clearance ahead of the ego's
    front (< 0: the boxes overlap), cos p, sin p)."""
    c = math.cos(p)
    sn = math.sin(p)
    if lateral_clear(y, c, sn, chl, chw, ehw):
        return False, np.nan, c, sn
    meets, lo, hi = band_range(x, y, c, sn, chl, chw, ehw)
    if not (meets and hi > s - ehl):
        return False, np.nan, c, sn
    return True, lo - (s + ehl), c, sn


@njit(cache=True)
def _penetration(t: float, t0: float, h: float, cs: FloatArray, cd: FloatArray,
                 cpsi: FloatArray, cv: FloatArray, es: FloatArray, ev: FloatArray,
                 t_b: float, jerk: float, a_max: float, ehl: float, ehw: float, chl: float,
                 chw: float) -> float:  # pragma: no cover - jit
    """Clearance ahead of the ego's front at time t when the cutter's box meets the ego's
    band beside or ahead of the ego (the boxes overlap exactly when it is < 0); NaN when it
    does not (no overlap either)."""
    x, y, p, _ = _cutter_at(t, t0, h, cs, cd, cpsi, cv)
    s, _ = ego_at(t, t0, h, es, ev, t_b, jerk, a_max)
    near, gap, _, _ = _clearance(x, y, p, s, ehl, ehw, chl, chw)
    return gap if near else np.nan


@njit(cache=True)
def _contact(t_lo: float, t_hi: float, t0: float, h: float, cs: FloatArray, cd: FloatArray,
             cpsi: FloatArray, cv: FloatArray, es: FloatArray, ev: FloatArray, t_b: float,
             jerk: float, a_max: float, ehl: float, ehw: float, chl: float,
             chw: float) -> tuple[float, float]:  # pragma: no cover - jit
    """The overlap's onset in (t_lo, t_hi] (no overlap at t_lo, overlap at t_hi), to the
    resolution of the time's floating-point numbers; (contact time, impact speed).

    A bracketing search on :func:`_penetration` (the clearance, continuous while the
    cutter meets the band): the Illinois variant of regula falsi, a bisection step
    whenever the clearance at the lower end is undefined or the bracket has not halved.
    """
    a = t_lo
    b = t_hi
    fa = _penetration(a, t0, h, cs, cd, cpsi, cv, es, ev, t_b, jerk, a_max, ehl, ehw, chl,
                      chw)
    fb = _penetration(b, t0, h, cs, cd, cpsi, cv, es, ev, t_b, jerk, a_max, ehl, ehw, chl,
                      chw)
    side = 0
    width = b - a
    for it in range(4 * _BISECT):
        if b - a <= 4e-16 * max(1.0, abs(b)):
            break
        secant = True
        if it % 4 == 3:  # bisect when the last four steps did not halve the bracket
            secant = b - a <= 0.5 * width
            width = b - a
        m = 0.5 * (a + b)
        if secant and not math.isnan(fa) and fa > fb:
            sec = b - fb * (b - a) / (fb - fa)
            if a < sec < b:
                m = sec
        if m <= a or m >= b:
            break
        fm = _penetration(m, t0, h, cs, cd, cpsi, cv, es, ev, t_b, jerk, a_max, ehl, ehw,
                          chl, chw)
        if fm < 0.0:  # overlap (NaN compares False)
            b = m
            fb = fm
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a = m
            fa = fm
            if side == 1:
                fb *= 0.5
            side = 1
    _, ve = ego_at(b, t0, h, es, ev, t_b, jerk, a_max)
    _, _, pc, vc = _cutter_at(b, t0, h, cs, cd, cpsi, cv)
    return b, math.hypot(ve - vc * math.cos(pc), vc * math.sin(pc))


@njit(cache=True)
def _tail_gap(t: float, t_k: float, gap_k: float, vx: float, s_k: float, t0: float,
              h: float, es: FloatArray, ev: FloatArray, t_b: float, jerk: float,
              a_max: float) -> tuple[float, float]:  # pragma: no cover - jit
    """Clearance and ego speed at t >= t_k in the analytic tail (cutter axis-parallel at
    constant speed vx, ego scripted at constant speed or braking from t_b)."""
    s, v = ego_at(t, t0, h, es, ev, t_b, jerk, a_max)
    return gap_k + vx * (t - t_k) - (s - s_k), v


@njit(cache=True)
def drive(t0: float, h: float, cs: FloatArray, cd: FloatArray, cpsi: FloatArray,
          cv: FloatArray, es: FloatArray, ev: FloatArray, ehl: float, ehw: float,
          chl: float, chw: float, t_b: float, jerk: float, a_max: float,
          t_from: float, k_const: int = -1,
          t_stop: float = np.inf) -> tuple[float, float, float]:  # pragma: no cover
    """One ego response against the cutter's actual motion on the grid.

    Returns (contact time or NaN, relative impact speed in m/s (0 without contact),
    minimum clearance in m over times >= ``t_from`` until contact (+inf: the cutter never
    is in the ego's band ahead; 0 with contact)). The contact time is refined between the
    grid steps by :func:`_contact` (ego states in closed form, cutter interpolated).

    ``k_const`` (>= 0): from grid step ``k_const`` on the cutter drives straight along the
    ego's heading (no lateral speed) at constant speed and the scripted ego at constant
    speed; the rest is then solved in closed form instead of stepping through the grid
    (the gap is linear, or convex once the ego brakes). -1: step through the whole grid.
    A contact after ``t_stop`` (s) does not count (the simulated time ends there).
    """
    n = cs.shape[0]
    last = n - 1 if k_const < 0 else min(k_const, n - 1)
    min_gap = np.inf
    for k in range(last + 1):
        t = t0 + k * h
        if t > t_b:
            s, _ = ego_at(t, t0, h, es, ev, t_b, jerk, a_max)
        else:
            s = es[k]
        near, gap, c, sn = _clearance(cs[k], cd[k], cpsi[k], s, ehl, ehw, chl, chw)
        if not near:
            continue
        if gap < 0.0:
            if k == 0:
                _, ve = ego_at(t0, t0, h, es, ev, t_b, jerk, a_max)
                return t0, math.hypot(ve - cv[0] * c, cv[0] * sn), 0.0
            tc, rel = _contact(t - h, t, t0, h, cs, cd, cpsi, cv, es, ev, t_b, jerk, a_max,
                               ehl, ehw, chl, chw)
            return tc, rel, 0.0
        if t >= t_from and gap < min_gap:
            min_gap = gap
    if k_const < 0:
        return np.nan, 0.0, min_gap
    return _drive_tail(last, t0, h, cs, cd, cpsi, cv, es, ev, ehl, ehw, chl, chw, t_b, jerk,
                       a_max, t_from, t_stop, min_gap)


@njit(cache=True)
def _drive_tail(k: int, t0: float, h: float, cs: FloatArray, cd: FloatArray,
                cpsi: FloatArray, cv: FloatArray, es: FloatArray, ev: FloatArray, ehl: float,
                ehw: float, chl: float, chw: float, t_b: float, jerk: float, a_max: float,
                t_from: float, t_stop: float,
                min_gap: float) -> tuple[float, float, float]:  # pragma: no cover - jit
    """:func:`drive` from grid step ``k`` on in closed form: the cutter straight along the
    ego's heading at constant speed, the scripted ego at constant speed (``min_gap``: the
    smallest clearance before ``k``)."""
    # closed-form tail from t_k: the cutter's band range moves at vx, the ego per ego_at
    t_k = t0 + k * h
    p = cpsi[k]
    meets, lo, hi = band_range(cs[k], cd[k], math.cos(p), math.sin(p), chl, chw, ehw)
    s_k, _ = ego_at(t_k, t0, h, es, ev, t_b, jerk, a_max)
    if not (meets and hi > s_k - ehl):
        return np.nan, 0.0, min_gap
    vx = cv[k] * math.cos(p)
    gap_k = lo - (s_k + ehl)
    # the gap is linear until braking starts, convex after: its minimum comes where the
    # ego's speed has fallen to vx (or never, when it does not brake)
    t_lin_end = t_b if t_b > t_k else t_k
    if math.isnan(t_b):
        if ev[k] <= vx:
            return np.nan, 0.0, min(min_gap, gap_k) if t_k >= t_from else min_gap
        tc = t_k + gap_k / (ev[k] - vx)
        if tc > t_stop:
            return np.nan, 0.0, min(min_gap, gap_k) if t_k >= t_from else min_gap
        return tc, ev[k] - vx, 0.0
    if t_lin_end > t_k:
        g_end, _ = _tail_gap(t_lin_end, t_k, gap_k, vx, s_k, t0, h, es, ev, t_b, jerk, a_max)
        if g_end < 0.0:
            tc = t_k + gap_k / (ev[k] - vx)
            if tc > t_stop:
                return np.nan, 0.0, min(min_gap, gap_k) if t_k >= t_from else min_gap
            return tc, ev[k] - vx, 0.0
    # the time the braking ego's speed reaches vx (or it stops), in closed form
    _, v_b = _ego_scripted(es, ev, t0, h, t_b)
    t_min = max(t_b + brake_time_to(v_b, jerk, a_max, vx), t_lin_end)
    g_min, _ = _tail_gap(t_min, t_k, gap_k, vx, s_k, t0, h, es, ev, t_b, jerk, a_max)
    if g_min >= 0.0:
        return np.nan, 0.0, min(min_gap, g_min) if t_min >= t_from else min_gap
    a = t_lin_end
    b = t_min
    for _ in range(_BISECT):
        m = 0.5 * (a + b)
        gm, _ = _tail_gap(m, t_k, gap_k, vx, s_k, t0, h, es, ev, t_b, jerk, a_max)
        if gm < 0.0:
            b = m
        else:
            a = m
    if b > t_stop:
        return np.nan, 0.0, min_gap
    _, vc_e = ego_at(b, t0, h, es, ev, t_b, jerk, a_max)
    return b, vc_e - vx, 0.0


@njit(cache=True)
def r157_critical(ahead: bool, g: float, clos: float,
                  ttc_crit: float) -> bool:  # pragma: no cover - jit
    """The R157 careful driver's condition "a conflict is developing".

    The cutter's centre is ahead (``ahead``) and the longitudinal gap ``g`` is already
    closed (<= 0) or closing (closing speed ``clos`` > 0) with TTC = g / clos below
    ``ttc_crit``. ``ttc_crit = +inf`` (the default setting): any closing gap, tested
    without arithmetic on inf.
    """
    if not ahead:
        return False
    if g <= 0.0:
        return True
    if not clos > 0.0:
        return False
    if ttc_crit == np.inf:
        return True
    return g < ttc_crit * clos


@njit(cache=True)
def _conflict_state(t: float, t0: float, h: float, cs: FloatArray, es: FloatArray,
                    ev: FloatArray, cv: FloatArray, cpsi: FloatArray,
                    half_lengths: float) -> tuple[bool, float, float]:  # pragma: no cover
    """At time t (arrays sampled every h from t0): is the cutter's centre ahead of the
    ego's, the longitudinal gap g = cs - es - (L_c + L_e)/2, and the closing speed."""
    x = interp(cs, t0, h, t)
    s = interp(es, t0, h, t)
    clos = interp(ev, t0, h, t) - interp(cv, t0, h, t) * math.cos(interp(cpsi, t0, h, t))
    return x > s, x - s - half_lengths, clos


@njit(cache=True)
def _r157_margin(g: float, clos: float, ttc_crit: float) -> float:  # pragma: no cover
    """A function of time that turns negative when :func:`r157_critical` becomes true
    (for a closing gap ahead): g - ttc_crit * clos, or -clos for ``ttc_crit = +inf``."""
    if ttc_crit == np.inf:
        return -clos
    return g - ttc_crit * clos


@njit(cache=True)
def r157_reaction_start(t0: float, h: float, cs: FloatArray, cpsi: FloatArray,
                        cv: FloatArray, es: FloatArray, ev: FloatArray, half_lengths: float,
                        t_p: float, ttc_crit: float, k_const: int = -1,
                        t_stop: float = np.inf) -> float:  # pragma: no cover - jit
    """First time >= t_p at which a conflict is developing for the scripted ego, NaN:
    never (see :func:`r157_critical`).

    The cutter's centre is ahead of the ego's and the longitudinal gap
    g = cs - es - (L_c + L_e)/2 is <= 0 or closing, with TTC < ttc_crit (+inf: any
    closing gap). Between grid steps the root of :func:`_r157_margin` (g - ttc_crit *
    closing, or -closing) is interpolated linearly (exact for speeds linear in time).
    """
    n = cs.shape[0]
    k0 = math.ceil((t_p - t0) / h - 1e-9)
    if k0 < 0:
        k0 = 0
    prev_t = t_p
    ahead, g, clos = _conflict_state(t_p, t0, h, cs, es, ev, cv, cpsi, half_lengths)
    if r157_critical(ahead, g, clos, ttc_crit):
        return t_p
    prev_f = _r157_margin(g, clos, ttc_crit)
    for k in range(k0, n):
        t = t0 + k * h
        if t <= t_p:
            continue
        clos = ev[k] - cv[k] * math.cos(cpsi[k])
        g = cs[k] - es[k] - half_lengths
        f = _r157_margin(g, clos, ttc_crit)
        if r157_critical(cs[k] > es[k], g, clos, ttc_crit):
            if g > 0.0 and prev_f > 0.0 and f < prev_f:
                return prev_t + (t - prev_t) * prev_f / (prev_f - f)
            return t
        prev_t = t
        prev_f = f
    if k_const >= 0:
        return _r157_tail(n - 1, t0 + (n - 1) * h, cs, cpsi, cv, es, ev, half_lengths, t_p,
                          ttc_crit, t_stop)
    return np.nan


@njit(cache=True)
def _r157_tail(k: int, t_k: float, cs: FloatArray, cpsi: FloatArray, cv: FloatArray,
               es: FloatArray, ev: FloatArray, half_lengths: float, t_p: float,
               ttc_crit: float, t_stop: float) -> float:  # pragma: no cover - jit
    """:func:`r157_reaction_start` after the last step ``k`` (time ``t_k``), all straight
    at constant speeds: the gap is linear, TTC falls to ``ttc_crit`` in closed form."""
    clos = ev[k] - cv[k] * math.cos(cpsi[k])
    g = cs[k] - es[k] - half_lengths
    if cs[k] > es[k] and clos > 0.0:
        if ttc_crit == np.inf:
            t_r = max(t_p, t_k)
        else:
            t_r = max(t_k + (g - ttc_crit * clos) / clos, t_p, t_k)
        if t_r <= t_stop:
            return t_r
    return np.nan


@njit(cache=True)
def _rss_danger(x: float, y: float, p: float, vc: float, s: float, ve: float, ehl: float,
                ehw: float, chl: float, chw: float, rho: float, a_acc: float, b_min: float,
                b_max: float, mu: float, a_lat: float) -> bool:  # pragma: no cover - jit
    """Both RSS distances violated (see :func:`rss_trigger`)."""
    if x <= s:
        return False
    c = math.cos(p)
    sn = math.sin(p)
    vf = max(vc * c, 0.0)
    d_long = (ve * rho + 0.5 * a_acc * rho * rho + (ve + rho * a_acc) ** 2 / (2.0 * b_min)
              - vf * vf / (2.0 * b_max))
    if x - s - ehl - chl >= d_long:
        return False
    lat_gap = abs(y) - ehw - (chl * abs(sn) + chw * abs(c))
    toward = -vc * sn if y > 0.0 else vc * sn
    v = max(toward, 0.0)
    d_lat = mu + (2.0 * v + a_lat * rho) * rho / 2.0 + (v + a_lat * rho) ** 2 / (2.0 * a_lat)
    return lat_gap < d_lat


@njit(cache=True)
def rss_trigger(t0: float, h: float, cs: FloatArray, cd: FloatArray, cpsi: FloatArray,
                cv: FloatArray, es: FloatArray, ev: FloatArray, ehl: float, ehw: float,
                chl: float, chw: float, rho: float, a_acc: float, b_min: float,
                b_max: float, mu: float, a_lat: float) -> float:  # pragma: no cover - jit
    """First time at which the scripted ego is in an RSS-dangerous situation, NaN: never.

    Longitudinal (Shalev-Shwartz et al. 2017, Def. 1): the cutter's centre is ahead and
    the gap g = cs - es - (L_c + L_e)/2 is below
    d_long = v_r rho + a_acc rho^2 / 2 + (v_r + rho a_acc)^2 / (2 b_min) - v_f^2 / (2 b_max)
    (v_r ego speed, v_f the cutter's speed along the ego's heading). Lateral: the lateral
    clearance between the boxes is below
    d_lat = mu + (2 v + a_lat rho) rho / 2 + (v + a_lat rho)^2 / (2 a_lat),
    v the cutter's lateral speed towards the ego (>= 0), the ego having none. Refined by
    bisection between the grid steps (cutter and ego interpolated).
    """
    n = cs.shape[0]
    for k in range(n):
        if not _rss_danger(cs[k], cd[k], cpsi[k], cv[k], es[k], ev[k], ehl, ehw, chl, chw,
                           rho, a_acc, b_min, b_max, mu, a_lat):
            continue
        if k == 0:
            return t0
        a = t0 + (k - 1) * h
        b = t0 + k * h
        for _ in range(_BISECT):
            m = 0.5 * (a + b)
            x, y, p, vc = _cutter_at(m, t0, h, cs, cd, cpsi, cv)
            if _rss_danger(x, y, p, vc, interp(es, t0, h, m), interp(ev, t0, h, m), ehl,
                           ehw, chl, chw, rho, a_acc, b_min, b_max, mu, a_lat):
                b = m
            else:
                a = m
        return b
    return np.nan


@njit(cache=True)
def required_decel(t0: float, h: float, cs: FloatArray, cd: FloatArray, cpsi: FloatArray,
                   cv: FloatArray, es: FloatArray, ev: FloatArray, ehl: float, ehw: float,
                   chl: float, chw: float, t_b: float,
                   k_const: int = -1) -> float:  # pragma: no cover - jit
    """Smallest constant deceleration from ``t_b`` on (after the scripted motion until
    ``t_b``) that keeps the ego's front behind the cutter inside its band at every grid
    time after ``t_b``; +inf when the clearance is already gone.

    For a clearance D available at tau = t - t_b from the ego's front at t_b, speed v_b:
    0 if v_b tau <= D; 2 (v_b tau - D) / tau^2 if the ego is still moving at tau
    (v_b tau <= 2 D); else v_b^2 / (2 D) (it stops before tau). With ``k_const`` (see
    :func:`drive`) the tail has D = D0 + vx tau and its supremum in closed form:
    (v_b - vx)^2 / (2 D0) at tau* = 2 D0 / (v_b - vx) when that lies in the tail.
    """
    n = cs.shape[0]
    last = n - 1 if k_const < 0 else min(k_const, n - 1)
    s_b, v_b = _ego_scripted(es, ev, t0, h, t_b)
    need = 0.0
    for k in range(last + 1):
        t = t0 + k * h
        if t <= t_b:
            continue
        near, d, _, _ = _clearance(cs[k], cd[k], cpsi[k], s_b, ehl, ehw, chl, chw)
        if not near:
            continue
        if d <= 0.0:
            return np.inf
        need = max(need, _decel_for(d, v_b, t - t_b))
    if k_const >= 0:
        need = max(need, _decel_tail(last, t0 + last * h, cs, cd, cpsi, cv, ehl, ehw, chl,
                                     chw, s_b, v_b, t_b))
    return need


@njit(cache=True)
def _decel_tail(k: int, t_k: float, cs: FloatArray, cd: FloatArray, cpsi: FloatArray,
                cv: FloatArray, ehl: float, ehw: float, chl: float, chw: float, s_b: float,
                v_b: float, t_b: float) -> float:  # pragma: no cover - jit
    """:func:`required_decel` after the last step ``k`` (time ``t_k``), the cutter
    straight at constant speed: the clearance is D0 + vx tau, its supremum in closed form
    (braking from speed ``v_b`` at ``s_b``, time ``t_b``)."""
    p = cpsi[k]
    meets, lo, hi = band_range(cs[k], cd[k], math.cos(p), math.sin(p), chl, chw, ehw)
    if meets and hi > s_b - ehl:
        vx = cv[k] * math.cos(p)
        tau_k = max(t_k - t_b, 0.0)
        d0 = lo - (s_b + ehl) - vx * (t_k - t_b)
        if v_b > vx and d0 > 0.0:
            tau_star = 2.0 * d0 / (v_b - vx)
            if tau_star >= tau_k:
                return (v_b - vx) ** 2 / (2.0 * d0)
    return 0.0


# --------------------------------------------------------------------------- pruned
# The same drivers on the same fine grid t_i = t0 + i h, h = D / r, for motions given as
# samples every D (the cutter and the scripted ego linear between samples, which is what
# the fine grid of such a scenario holds). A cheap bound per sample interval proves most
# intervals free of the event looked for; only the others are stepped through at h.
# Interval j (times [t0 + j D, t0 + (j + 1) D]) owns the grid points j r .. j r + r - 1
# (the last interval its end point too).

_MARGIN = 1e-9  # m (or m/s): the bounds skip an interval only by more than this


@njit(cache=True)
def _grid_index(i: int, r: int, n_s: int) -> tuple[int, float]:  # pragma: no cover - jit
    """Sample interval and fraction of fine grid point i (the end point: last interval)."""
    k = i // r
    if k >= n_s - 1:
        return n_s - 2, 1.0
    return k, (i - k * r) / r


@njit(cache=True)
def _lin(a: FloatArray, k: int, f: float) -> float:  # pragma: no cover - jit
    return a[k] * (1.0 - f) + a[k + 1] * f


@njit(cache=True)
def _extents(cpsi: FloatArray, j: int, chl: float,
             chw: float) -> tuple[float, float]:  # pragma: no cover - jit
    """Upper bounds of the cutter box's half-extents along and across the ego's heading
    over interval j: |cos| <= 1 and |sin p| <= min(|p|, 1), p linear in the interval."""
    sp = min(max(abs(cpsi[j]), abs(cpsi[j + 1])), 1.0)
    return chl + chw * sp, chw + chl * sp


@njit(cache=True)
def _laterally_clear_interval(cd: FloatArray, j: int, lat: float,
                              ehw: float) -> bool:  # pragma: no cover - jit
    """The cutter's box stays outside the ego's band over interval j (cd linear)."""
    a = cd[j]
    b = cd[j + 1]
    d_min = 0.0 if a * b <= 0.0 else min(abs(a), abs(b))
    return d_min - lat > ehw + _MARGIN


@njit(cache=True)
def drive_pruned(t0: float, d_s: float, r: int, cs: FloatArray, cd: FloatArray,
                 cpsi: FloatArray, cv: FloatArray, es: FloatArray, ev: FloatArray,
                 ehl: float, ehw: float, chl: float, chw: float, t_b: float, jerk: float,
                 a_max: float, i_start: int, closed_tail: bool,
                 t_stop: float) -> tuple[float, float]:  # pragma: no cover - jit
    """:func:`drive` (contact time or NaN, impact speed) from fine grid point ``i_start``
    on, for arrays sampled every ``d_s`` (see the section's comment); ``closed_tail``: the
    closed-form tail of :func:`drive` after the last sample (its ``k_const``).

    An interval is skipped when the cutter's box, bounded by the extents of
    :func:`_extents` around its centre, stays outside the ego's band or entirely ahead of
    the ego's front at the interval's end or behind its rear at the start (the ego never
    moves backwards). The grid points of the other intervals are checked as in
    :func:`drive`, the contact refined by the same :func:`_contact`.
    """
    h = d_s / r
    n_s = cs.shape[0]
    i_end = (n_s - 1) * r
    radius = math.hypot(chl, chw)
    rate = np.empty(0)  # see below: computed when first needed
    for j in range(i_start // r, n_s - 1):
        lon, lat = _extents(cpsi, j, chl, chw)
        if _laterally_clear_interval(cd, j, lat, ehw):
            continue
        t_j = t0 + j * d_s
        if not t_j + d_s > t_b:  # scripted throughout (also t_b NaN): linear
            s_lo = es[j]
            g_a = cs[j] - es[j]
            g_b = cs[j + 1] - es[j + 1]
        else:  # braking from within or before: speeds at most v_up from t_j on
            s_lo, v_lo = ego_at(t_j, t0, d_s, es, ev, t_b, jerk, a_max)
            v_up = v_lo if t_j >= t_b else max(ev[j], ev[j + 1])
            g_a = cs[j] - s_lo
            g_b = cs[j + 1] - s_lo - v_up * d_s
            if t_j >= t_b and g_a - radius - ehl > _MARGIN:
                # the cutter entirely ahead of the braking ego and never slower than it
                # from here on (rate: the slowest advance of its centre): no contact
                if rate.shape[0] == 0:
                    rate = np.empty(n_s)
                    rate[n_s - 1] = (cv[n_s - 1] * math.cos(cpsi[n_s - 1]) if closed_tail
                                     else np.inf)
                    for q in range(n_s - 2, -1, -1):
                        rate[q] = min(rate[q + 1], (cs[q + 1] - cs[q]) / d_s)
                if rate[j] >= v_lo:
                    return np.nan, 0.0
        if min(g_a, g_b) - lon - ehl > _MARGIN:  # ahead of the ego's front throughout
            continue
        if max(cs[j], cs[j + 1]) + lon < s_lo - ehl - _MARGIN:  # behind its rear
            continue
        i_hi = j * r + r - 1 if j < n_s - 2 else i_end
        for i in range(max(j * r, i_start), i_hi + 1):
            k, f = _grid_index(i, r, n_s)
            t = t0 + i * h
            if t > t_b:
                s, _ = ego_at(t, t0, d_s, es, ev, t_b, jerk, a_max)
            else:
                s = _lin(es, k, f)
            near, gap, c, sn = _clearance(_lin(cs, k, f), _lin(cd, k, f), _lin(cpsi, k, f),
                                          s, ehl, ehw, chl, chw)
            if near and gap < 0.0:
                if i == i_start:
                    _, ve = ego_at(t, t0, d_s, es, ev, t_b, jerk, a_max)
                    vc = _lin(cv, k, f)
                    return t, math.hypot(ve - vc * c, vc * sn)
                return _contact(t - h, t, t0, d_s, cs, cd, cpsi, cv, es, ev, t_b, jerk,
                                a_max, ehl, ehw, chl, chw)
    if not closed_tail:
        return np.nan, 0.0
    tc, rel, _ = _drive_tail(n_s - 1, t0, d_s, cs, cd, cpsi, cv, es, ev, ehl, ehw, chl,
                             chw, t_b, jerk, a_max, t0, t_stop, np.inf)
    return tc, rel


@njit(cache=True)
def r157_reaction_start_pruned(t0: float, d_s: float, r: int, cs: FloatArray,
                               cpsi: FloatArray, cv: FloatArray, es: FloatArray,
                               ev: FloatArray, half_lengths: float, t_p: float,
                               ttc_crit: float, closed_tail: bool,
                               t_stop: float) -> float:  # pragma: no cover - jit
    """:func:`r157_reaction_start` on the fine grid of arrays sampled every ``d_s``.

    An interval is skipped when no grid point in it can be critical: the cutter is not
    ahead at either end (cs - es is linear), or the gap stays > 0 and an upper bound of
    the closing speed (the ego's largest speed minus a lower bound of the cutter's speed
    along the ego's heading) is < 0, or, for a finite ``ttc_crit``, the smallest gap
    exceeds ``ttc_crit`` times that bound.
    """
    h = d_s / r
    n_s = cs.shape[0]
    i_end = (n_s - 1) * r
    ahead, g, clos = _conflict_state(t_p, t0, d_s, cs, es, ev, cv, cpsi, half_lengths)
    if r157_critical(ahead, g, clos, ttc_crit):
        return t_p
    i0 = max(math.ceil((t_p - t0) / h - 1e-9), 0)
    prev_t = t_p
    prev_f = _r157_margin(g, clos, ttc_crit)
    prev_i = -1  # the fine grid point prev_t belongs to (-1: t_p itself)
    for j in range(i0 // r, n_s - 1):
        a = cs[j] - es[j]
        b = cs[j + 1] - es[j + 1]
        if a < -_MARGIN and b < -_MARGIN:
            continue
        g_min = min(a, b) - half_lengths
        if g_min > _MARGIN:
            pm = min(max(abs(cpsi[j]), abs(cpsi[j + 1])), math.pi)
            cmin = math.cos(pm)
            along = cmin * (min(cv[j], cv[j + 1]) if cmin >= 0.0 else max(cv[j], cv[j + 1]))
            clos_max = max(ev[j], ev[j + 1]) - along
            if clos_max < -_MARGIN:
                continue
            if ttc_crit < np.inf and g_min - ttc_crit * max(clos_max, 0.0) > _MARGIN:
                continue
        i_hi = j * r + r - 1 if j < n_s - 2 else i_end
        for i in range(max(j * r, i0), i_hi + 1):
            t = t0 + i * h
            if t <= t_p:
                continue
            if prev_i != i - 1 and t - h > t_p:
                # the previous grid point lies in a skipped interval: its value
                kp, fp = _grid_index(i - 1, r, n_s)
                prev_t = t - h
                prev_f = _r157_margin(_lin(cs, kp, fp) - _lin(es, kp, fp) - half_lengths,
                                      _lin(ev, kp, fp) - _lin(cv, kp, fp)
                                      * math.cos(_lin(cpsi, kp, fp)), ttc_crit)
            k, f = _grid_index(i, r, n_s)
            xs = _lin(cs, k, f)
            se = _lin(es, k, f)
            clos = _lin(ev, k, f) - _lin(cv, k, f) * math.cos(_lin(cpsi, k, f))
            g = xs - se - half_lengths
            fv = _r157_margin(g, clos, ttc_crit)
            if r157_critical(xs > se, g, clos, ttc_crit):
                if g > 0.0 and prev_f > 0.0 and fv < prev_f:
                    return prev_t + (t - prev_t) * prev_f / (prev_f - fv)
                return t
            prev_t = t
            prev_f = fv
            prev_i = i
    if closed_tail:
        return _r157_tail(n_s - 1, t0 + (n_s - 1) * d_s, cs, cpsi, cv, es, ev, half_lengths,
                          t_p, ttc_crit, t_stop)
    return np.nan


@njit(cache=True)
def _decel_for(d: float, v_b: float, tau: float) -> float:  # pragma: no cover - jit
    """Constant deceleration from speed v_b that covers at most d (> 0) in tau: see
    :func:`required_decel`."""
    run = v_b * tau
    if run <= d:
        return 0.0
    return 2.0 * (run - d) / (tau * tau) if run <= 2.0 * d else v_b * v_b / (2.0 * d)


@njit(cache=True)
def _decel_bound(c0: float, slope: float, v_b: float, tau_a: float,
                 tau_b: float) -> float:  # pragma: no cover - jit
    """Largest :func:`_decel_for` over tau in [tau_a, tau_b] (tau_b > 0) for the clearance
    c0 + slope tau; +inf when that clearance is not > 0 throughout.

    The deceleration is 0 while v_b tau <= d, 2 (v_b tau - d) / tau^2 while
    v_b tau <= 2 d (one stationary point, at tau = 2 c0 / (v_b - slope)) and v_b^2 / (2 d)
    beyond (monotone in tau); it is continuous, so its largest value is at an end, at
    that stationary point or where v_b tau = 2 d (tau = 2 c0 / (v_b - 2 slope)).
    """
    lo = max(tau_a, 1e-12)
    d_a = c0 + slope * lo
    d_b = c0 + slope * tau_b
    if d_a <= _MARGIN or d_b <= _MARGIN:
        return np.inf
    best = max(_decel_for(d_a, v_b, lo), _decel_for(d_b, v_b, tau_b))
    for den in (v_b - slope, v_b - 2.0 * slope):
        if den != 0.0:
            tau = 2.0 * c0 / den
            if lo < tau < tau_b:
                best = max(best, _decel_for(c0 + slope * tau, v_b, tau))
    return best


@njit(cache=True)
def required_decel_pruned(t0: float, d_s: float, r: int, cs: FloatArray, cd: FloatArray,
                          cpsi: FloatArray, cv: FloatArray, es: FloatArray, ev: FloatArray,
                          ehl: float, ehw: float, chl: float, chw: float, t_b: float,
                          closed_tail: bool) -> float:  # pragma: no cover - jit
    """:func:`required_decel` on the fine grid of arrays sampled every ``d_s``.

    The deceleration needed for a clearance d at tau after t_b falls with d and does not
    fall with tau, so over an interval it is at most its value for the smallest possible
    clearance (the cutter's centre minus its extent bound) at the interval's end. The
    intervals are stepped through in the order of that bound, largest first, until the
    bound cannot beat the maximum found (a bound of +inf: the clearance may be gone).
    """
    h = d_s / r
    n_s = cs.shape[0]
    i_end = (n_s - 1) * r
    s_b, v_b = _ego_scripted(es, ev, t0, d_s, t_b)
    front = s_b + ehl
    i0 = max(math.floor((t_b - t0) / h) - 1, 0)
    m = n_s - 1
    bound = np.full(m, -1.0)
    for j in range(i0 // r, m):
        t_hi = t0 + (j + 1) * d_s
        if t_hi <= t_b:
            continue
        lon, lat = _extents(cpsi, j, chl, chw)
        if _laterally_clear_interval(cd, j, lat, ehw):
            continue
        if max(cs[j], cs[j + 1]) + lon < s_b - ehl - _MARGIN:
            continue
        # clearance >= L(tau) = c0 + slope * tau (centre linear, extent bounded)
        slope = (cs[j + 1] - cs[j]) / d_s
        c0 = cs[j] - lon - front - slope * (t0 + j * d_s - t_b)
        bound[j] = _decel_bound(c0, slope, v_b, max(t0 + j * d_s - t_b, 0.0), t_hi - t_b)
    need = 0.0
    while True:
        j = int(np.argmax(bound))
        if bound[j] < 0.0 or bound[j] <= need:
            break
        bound[j] = -1.0
        i_hi = j * r + r - 1 if j < m - 1 else i_end
        for i in range(max(j * r, i0), i_hi + 1):
            t = t0 + i * h
            if t <= t_b:
                continue
            k, f = _grid_index(i, r, n_s)
            near, d, _, _ = _clearance(_lin(cs, k, f), _lin(cd, k, f), _lin(cpsi, k, f), s_b,
                                       ehl, ehw, chl, chw)
            if not near:
                continue
            if d <= 0.0:
                return np.inf
            need = max(need, _decel_for(d, v_b, t - t_b))
    if closed_tail:
        need = max(need, _decel_tail(n_s - 1, t0 + (n_s - 1) * d_s, cs, cd, cpsi, cv, ehl,
                                     ehw, chl, chw, s_b, v_b, t_b))
    return need


@njit(cache=True)
def ego_track(tq: FloatArray, t0: float, h: float, es: FloatArray, ev: FloatArray,
              t_b: float, jerk: float,
              a_max: float) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - jit
    """:func:`ego_at` at every time of ``tq``: arc lengths and speeds."""
    s = np.empty(tq.shape[0])
    v = np.empty(tq.shape[0])
    for i in range(tq.shape[0]):
        s[i], v[i] = ego_at(tq[i], t0, h, es, ev, t_b, jerk, a_max)
    return s, v


@njit(cache=True)
def scene_risk(ox: float, oy: float, opsi: float, ov: float, mean_a: float, std_a: float,
               mean_w: float, std_w: float, za: FloatArray, zw: FloatArray,
               weight: FloatArray, ohl: float, ohw: float, ex: FloatArray, ey: FloatArray,
               epsi: FloatArray, ev: FloatArray, ehl: float, ehw: float, man_a: FloatArray,
               man_w: FloatArray, dt: float, t_pnr: float, t_max: float,
               m: float) -> float:  # pragma: no cover - jit
    """r_k of one object in one scene: riskcore's engine (``scene._Engine.object``) in one
    compiled call, for the scenes of a one-object scenario (there r_dep = r_ind = r_k)."""
    n = ex.shape[0] - 1
    a = mean_a + std_a * za
    w = mean_w + std_w * zw
    traj = _kernels.predict(ox, oy, opsi, ov, a, w, n, dt)
    poses = _kernels.ego_poses(ex, ey, epsi)
    n_man = man_a.shape[1]
    eva = np.empty((n, n_man, n + 1, 4))
    done = np.zeros((n, n_man), dtype=np.bool_)
    first, react, _ = _kernels.ttr_scan(traj, ohl, ohw, poses, ev, ehl, ehw, man_a, man_w,
                                        dt, eva, done)
    _, _, _, risk = _kernels.finish(first, react, dt, t_pnr, t_max, m, weight)
    return risk


@njit(cache=True)
def scene_risks(ox: FloatArray, oy: FloatArray, opsi: FloatArray, ov: FloatArray,
                dist: FloatArray, za: FloatArray, zw: FloatArray, weight: FloatArray,
                ohl: float, ohw: float, ex: FloatArray, ey: FloatArray, epsi: FloatArray,
                ev: FloatArray, ehl: float, ehw: float, man_a: FloatArray, man_w: FloatArray,
                dt: float, t_pnr: float, t_max: float, m: float, level: float,
                out: FloatArray) -> int:  # pragma: no cover - jit
    """:func:`scene_risk` of the scenes ``b = 0, 1, ...`` (row b of every array: the
    object's state, ``dist[b]`` = mean_a, std_a, mean_w, std_w, the ego's future and the
    manoeuvres' inputs) in order, until one reaches ``level``: ``out[b]`` its risk (rows
    after it are left as they were). Returns the number of scenes computed."""
    for b in range(ex.shape[0]):
        r = scene_risk(ox[b], oy[b], opsi[b], ov[b], dist[b, 0], dist[b, 1], dist[b, 2],
                       dist[b, 3], za, zw, weight, ohl, ohw, ex[b], ey[b], epsi[b], ev[b],
                       ehl, ehw, man_a[b], man_w[b], dt, t_pnr, t_max, m)
        out[b] = r
        if r >= level:
            return b + 1
    return ex.shape[0]
