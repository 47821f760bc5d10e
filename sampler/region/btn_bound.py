"""An upper bound of ``a_req`` (and ``btn``) from the kinematics alone: no simulation.

``a_req`` (docs/criticality.md) is the constant deceleration the ego needs when it starts
braking at ``t_b = t_p + reaction_time`` to stay behind the cutter. It costs a closed-loop
simulation per vector. A region such as ``btn > 0.4`` is rare (1.6e-5 on the TNO model),
and almost every vector is far from it: the cutter is well ahead, or faster, and does not
brake. ``a_req_bound`` proves that for most vectors from their parameters, so plain Monte
Carlo simulates only the few vectors whose bound reaches the threshold, and stays exact:
``btn > c`` implies ``btn_bound >= c``, so adding ``btn_bound >= c`` to the free part of a
region changes no hit (``sampler.methods.probability``).

Why it is an upper bound. Four relaxations, each of which can only raise the result:

1. **Later braking.** ``t_p`` is bounded from above by the time the cutter's centre has
   moved ``wandering_zone`` laterally, found on this module's own grid (the crossing
   kernel's trapezoid rule, ~1e-4 s from the builder's motion) plus ``T_MARGIN``, which
   also covers the criticality's linear interpolation between the 0.1 s samples. Braking
   later never needs less deceleration: with the same deceleration the later-braking ego
   is ahead of the earlier one at every moment.
2. **A cutter further back.** Its rear is bounded from below: the centre's x-progress is
   ``int v cos psi`` >= ``int v cos psi_max`` during the lane change (``psi_max`` the peak
   heading), ``= int v`` after it and ``<= int v`` before the crossing moment (where the
   gap is given); its rearmost corner is at most ``half_width sin psi_max`` behind the
   centre-line rear; ``X_MARGIN`` covers the linear interpolation between samples.
3. **A cutter always in the ego's band** from the moment it *could* first be in it: the
   box can reach the band ``|y| <= ego half width`` only once its centre has moved
   ``lane_width - ego_half_width - half_width - half_length sin psi_max`` laterally (minus
   ``Y_MARGIN``); from then on every moment counts (the simulation counts only those at
   which the box is in the band).
4. **Times between grid points.** The clearance ``D(t)`` = cutter rear - ego front at
   ``t_b`` never falls (the cutter does not reverse), and the needed deceleration
   ``decel_for(D, v, t - t_b)`` falls with D and does not fall with t: over a grid
   interval it is at most its value at (D at the start, t at the end). After the cutter's
   last change of speed or heading, D grows linearly and the supremum is in closed form.

With a limit (``stop_at``), two looser bounds settle most rows first, in O(1): from the
speeds alone (the cutter's within its two plateaus; braking at most the reaction time
after the crossing, since t_p comes before it), then with t_p, the crossing and the first
moment in the band bracketed in closed form (``|y|`` lies between ``k Psi(t)`` for two
constants k, ``Psi(t) = t - (p_t / pi) sin(pi t / p_t)``).

Before ``t_b`` the ego drives at its scripted constant speed: if the relaxed cutter could
be touched then, the bound is +inf (the simulation's ``a_req`` is +inf when contact comes
before ``t_b``). A vector that is not a buildable cut-in (no crossing, a negative speed)
gets +inf, so the full evaluation decides. The property is tested against
``criticality_quantities`` on model draws and on random vectors (tests/sampler).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from riskcore import jit
from riskcore.criticality import CriticalitySettings
from sampler.errors import SamplerError
from sampler.region.kinematics import DEFAULT_N_GRID, _one_minus_cos
from sampler.scenario.builder import DEFAULT_VEHICLE_SIZE

jit.register(__file__)

__all__ = ["a_req_bound", "btn_bound"]

FloatArray = NDArray[np.float64]

#: s added to the bound of t_p (the simulation interpolates the 0.1 s samples linearly)
T_MARGIN = 0.03
#: m taken off the cutter's rear (linear interpolation of its position between samples)
X_MARGIN = 0.05
#: m taken off the lateral movement at which the cutter may first meet the ego's band
Y_MARGIN = 0.02
#: s, grid step of the longitudinal bound
H_FINE = 0.02


class _Row(NamedTuple):
    """What the looser bounds read of a row: p_t, dv and gap, the cutter's speeds before
    and after its pulse, |amp| = |p_y1| p_t / pi, the peak heading, the rear's extent
    (m) and the lateral move at which the box may first meet the ego's band (m)."""

    p_t: float
    dv: float
    gap: float
    before: float
    after: float
    amp: float
    psi_max: float
    extent: float
    y_band: float


class _Relaxed(NamedTuple):
    """The relaxed cutter (relaxation 2): its crossing moment, the distance it has covered
    by then and by the end of the lane change, the shrink 1 - cos psi_max of its
    x-progress in between, the gap less its rear's extent, and its speed profile (the
    arguments of :func:`_speed` after tau)."""

    tau_c: float
    s_c: float
    s_lc: float
    shrink: float
    d_c: float
    p_a1: float
    p_a2: float
    p_a3: float
    p_v0: float
    c0: float


class _Setup(NamedTuple):
    """What every row's bound shares: the road, the criticality's settings, the boxes."""

    lane_width: float
    wandering: float  # wandering zone (m)
    reaction: float  # reaction time (s)
    ehw: float  # the ego's half width
    chl: float  # the cutter's half length ...
    chw: float  # ... and half width
    stop_at: float  # > 0: a looser bound below it settles the row


@numba.njit(cache=True, nogil=True)
def _quick_bound(row: _Row, window: float,
                 delay: float) -> float:  # pragma: no cover - compiled
    """A looser bound in O(1) from speeds alone: the cutter's speed stays within [min,
    max] of its two plateaus (times cos psi_max along x), the ego's is the cutter's at the
    crossing plus ``dv``; ``window``: how long before the crossing the cutter may be in the
    band or the ego may brake; ``delay``: how long after the crossing braking may start."""
    dv, gap, before, after = row.dv, row.gap, row.before, row.after
    psi_max, extent = row.psi_max, row.extent
    v_hi = max(before, after)
    v_lo = min(before, after) * math.cos(psi_max)
    ve_hi = v_hi + dv
    ve_lo = min(before, after) + dv
    if not ve_hi > 0.0:
        return np.inf
    d = gap - extent
    # before the crossing: the cutter, faster than the ego, was further back
    d_pre = d - max(v_hi - ve_lo, 0.0) * window
    # after it: the clearance closed at most at (ve_hi - v_lo) until braking starts
    d_b = min(d_pre, d - max(ve_hi - v_lo, 0.0) * delay)
    if d_b <= 0.0:
        return np.inf
    if ve_hi <= v_lo:
        return 0.0
    return (ve_hi - v_lo) ** 2 / (2.0 * d_b)


@numba.njit(cache=True, nogil=True)
def _psi_inv(target: float, p_t: float, upper: bool) -> float:  # pragma: no cover
    """The time t in [0, 2 p_t] at which Psi(t) = t - (p_t / pi) sin(pi t / p_t) (rising
    from 0 to 2 p_t) reaches ``target``, bracketed by bisection to 2 p_t / 2^10: the
    bracket's upper end when ``upper``, else its lower end; 2 p_t (upper) or NaN (lower)
    when it is not reached."""
    if target <= 0.0:
        return 0.0
    if target >= 2.0 * p_t:
        return 2.0 * p_t if upper else np.nan
    lo, hi = 0.0, 2.0 * p_t
    for _ in range(10):
        mid = 0.5 * (lo + hi)
        if mid - p_t / np.pi * math.sin(np.pi * mid / p_t) < target:
            lo = mid
        else:
            hi = mid
    return hi if upper else lo


@numba.njit(cache=True, nogil=True)
def _bracket_bound(row: _Row, cfg: _Setup) -> float:  # pragma: no cover - compiled
    """:func:`_quick_bound` with the lateral moments bracketed in closed form: |y(t)| =
    int v |sin psi| lies between k_lo Psi(t) and k_hi Psi(t) (v within its plateaus,
    psi - psi^3 / 6 <= sin psi <= psi, |psi| = amp (1 - cos(pi t / p_t))), which brackets
    t_p, the crossing and the first moment in the band."""
    p_t, before, after, amp, psi_max = row.p_t, row.before, row.after, row.amp, row.psi_max
    lane_width, y_band, wandering, reaction = (cfg.lane_width, row.y_band, cfg.wandering,
                                               cfg.reaction)
    k_lo = min(before, after) * (1.0 - psi_max * psi_max / 6.0) * amp
    k_hi = max(before, after) * amp
    if not (k_lo > 0.0 and k_hi > 0.0):
        return np.inf
    y_cross = 0.5 * lane_width
    c_lo = _psi_inv(y_cross / k_hi, p_t, False)
    if np.isnan(c_lo):
        return np.inf  # it never crosses: not buildable, the evaluation decides
    c_hi = _psi_inv(y_cross / k_lo, p_t, True)
    tp_lo = _psi_inv(wandering / k_hi, p_t, False)
    tp_hi = min(_psi_inv(wandering / k_lo, p_t, True), c_hi)
    if y_band <= 0.0:
        e_lo = 0.0
    else:
        e_lo = _psi_inv(y_band / k_hi, p_t, False)
        if np.isnan(e_lo):
            return 0.0  # the box never reaches the ego's band
    first = min(e_lo, tp_lo - T_MARGIN + reaction)
    window = max(c_hi - first, 0.0)
    delay = max(tp_hi + T_MARGIN + reaction - c_lo, 0.0)
    return _quick_bound(row, window, delay)


@numba.njit(cache=True, nogil=True)
def _decel_for(d: float, v: float, tau: float) -> float:  # pragma: no cover - compiled
    """Constant deceleration from speed ``v`` that keeps the front behind a clearance ``d``
    available ``tau`` after braking starts (riskcore's rule)."""
    if d <= 0.0:
        return np.inf
    if v * tau <= d:
        return 0.0
    if v * tau <= 2.0 * d:
        return 2.0 * (v * tau - d) / (tau * tau)
    return v * v / (2.0 * d)


@numba.njit(cache=True, nogil=True)
def _h(u: float, a3: float) -> float:  # pragma: no cover - compiled
    """int_{-inf}^{u} clip(s, 0, a3) ds."""
    if u <= 0.0:
        return 0.0
    if u <= a3:
        return 0.5 * u * u
    return 0.5 * a3 * a3 + a3 * (u - a3)


@numba.njit(cache=True, nogil=True)
def _dist(tau: float, p_a1: float, p_a2: float, p_a3: float, p_v0: float,
          c0: float) -> float:  # pragma: no cover - compiled
    """int_0^tau v(s) ds for the cutter's speed v(s) = p_v0 + p_a1 (clip(s - p_a2, 0, p_a3)
    - c0)."""
    return (p_v0 - p_a1 * c0) * tau + p_a1 * (_h(tau - p_a2, p_a3) - _h(-p_a2, p_a3))


@numba.njit(cache=True, nogil=True)
def _rear(tau: float, rel: _Relaxed) -> float:  # pragma: no cover - compiled
    """Lower bound of the cutter's rear minus the ego's front at the crossing moment
    ``rel.tau_c``, at ``tau`` (relaxation 2; ``rel.d_c``: the gap less the rear's
    extent)."""
    s = _dist(tau, rel.p_a1, rel.p_a2, rel.p_a3, rel.p_v0, rel.c0)
    if tau <= rel.tau_c:
        return rel.d_c + (s - rel.s_c)
    return rel.d_c + (s - rel.s_c) - rel.shrink * max(min(s, rel.s_lc) - rel.s_c, 0.0)


@numba.njit(cache=True, nogil=True)
def _scan(h: float, t0: float, t_b: float, t_end: float, v_e: float,
          rel: _Relaxed) -> float:  # pragma: no cover - compiled
    """Relaxation 4 on a grid of step ``h`` from ``t0`` (the band may be met) to ``t_end``
    (the cutter's motion is settled): +inf when the unbraked ego could touch the relaxed
    cutter before ``t_b``, else the largest needed deceleration."""
    need = 0.0
    n = max(math.ceil((t_end - t0) / h - 1e-9), 1)
    front_b = v_e * (t_b - rel.tau_c)
    for j in range(n):
        lo = t0 + j * h
        hi = min(t0 + (j + 1) * h, t_end) if j < n - 1 else t_end
        r_lo = _rear(lo, rel)
        if lo < t_b:
            # the scripted ego at constant speed until t_b: touching then gives +inf
            if r_lo - v_e * (min(hi, t_b) - rel.tau_c) <= 0.0:
                return np.inf
            if hi <= t_b:
                continue
            r_lo = _rear(t_b, rel)
        need = max(need, _decel_for(r_lo - front_b, v_e, hi - t_b))
    return need


@numba.njit(cache=True, nogil=True)
def _lateral_moments(row: FloatArray, c0: float, amp: float, one_minus_cos: FloatArray,
                     levels: tuple[float, float, float]
                     ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """The model times at which the cutter's centre has moved each of ``levels``
    (wandering zone, band, crossing) laterally, on the crossing kernel's grid
    (trapezoid rule, linear between grid points): (tau_p, tau_e, tau_c), NaN when not
    reached before the crossing; tau_e 0 for a band at or below 0."""
    wandering, y_band, y_cross = levels
    p_t, p_a1, p_a2, p_a3, p_v0 = row[1], row[2], row[3], row[4], row[5]
    n_grid = one_minus_cos.shape[0] - 1
    du = 2.0 / n_grid
    h_lat = p_t * du
    y = 0.0
    f_prev = 0.0
    tau_p = np.nan
    tau_c = np.nan
    tau_e = 0.0 if y_band <= 0.0 else np.nan
    for i in range(1, n_grid + 1):
        v = _speed(p_t * i * du, p_a1, p_a2, p_a3, p_v0, c0)
        f = v * math.sin(amp * one_minus_cos[i])
        y_new = y + 0.5 * (f + f_prev) * h_lat
        a0, a1 = abs(y), abs(y_new)
        if np.isnan(tau_p) and a1 >= wandering:
            tau_p = (i - 1 + (wandering - a0) / (a1 - a0)) * du * p_t
        if np.isnan(tau_e) and a1 >= y_band:
            tau_e = (i - 1 + (y_band - a0) / (a1 - a0)) * du * p_t
        if np.isnan(tau_c) and a1 >= y_cross:
            tau_c = (i - 1 + (y_cross - a0) / (a1 - a0)) * du * p_t
            if not np.isnan(tau_e):
                break  # t_p <= the crossing moment: all three are known
        y = y_new
        f_prev = f
    return tau_p, tau_e, tau_c


@numba.njit(cache=True, nogil=True)
def _tight_bound(rel: _Relaxed, v_e: float, t_b: float, tau_e: float, p_t: float,
                 after: float) -> float:  # pragma: no cover - compiled
    """Relaxations 3 and 4: the grid scan from the first moment in the band ``tau_e`` to
    the end of the cutter's motion, then the tail (speed ``after``, clearance D0 + after
    tau from t_b) in closed form."""
    t_end = max(2.0 * p_t, rel.p_a2 + rel.p_a3, t_b, tau_e) + H_FINE
    need = _scan(H_FINE, tau_e, t_b, t_end, v_e, rel)
    if np.isfinite(need):
        d_end = _rear(t_end, rel) - v_e * (t_b - rel.tau_c)
        d0 = d_end - after * (t_end - t_b)
        if v_e > after and d0 > 0.0 and 2.0 * d0 / (v_e - after) >= t_end - t_b:
            need = max(need, (v_e - after) ** 2 / (2.0 * d0))
    return need


@numba.njit(cache=True, nogil=True)
def _bound_row(row: FloatArray, cfg: _Setup,
               one_minus_cos: FloatArray) -> float:  # pragma: no cover - compiled
    """The bound of one row: +inf when it is not a buildable cut-in (the evaluation
    decides); with ``cfg.stop_at``, a looser bound below it when one settles the row."""
    p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap = (row[0], row[1], row[2], row[3], row[4],
                                                  row[5], row[6], row[7])
    ok = p_t > 0.0 and p_a3 >= 0.0
    for j in range(8):
        if not np.isfinite(row[j]):
            ok = False
    c0 = min(max(-p_a2, 0.0), p_a3)
    before = p_v0 - p_a1 * c0
    after = before + p_a1 * p_a3
    amp = p_y1 * p_t / np.pi
    psi_max = 2.0 * abs(amp)
    if not ok or before < 0.0 or after < 0.0 or psi_max >= 0.5 * np.pi:
        return np.inf
    extent = cfg.chw * math.sin(psi_max) + X_MARGIN
    y_band = cfg.lane_width - cfg.ehw - cfg.chw - cfg.chl * math.sin(psi_max) - Y_MARGIN
    if cfg.stop_at > 0.0:
        # cheaper, looser bounds first: below what is asked, they settle the row.
        # Speeds alone (t_p and the crossing lie in [0, 2 p_t], t_p before the
        # crossing: braking at most the reaction time after it) ...
        loose = _Row(p_t, dv, gap, before, after, abs(amp), psi_max, extent, y_band)
        quick = _quick_bound(loose, 2.0 * p_t, cfg.reaction + T_MARGIN)
        if quick < cfg.stop_at:
            return quick
        # ... then with the lateral moments bracketed in closed form
        quick = _bracket_bound(loose, cfg)
        if quick < cfg.stop_at:
            return quick
    tau_p, tau_e, tau_c = _lateral_moments(row, c0, amp, one_minus_cos,
                                           (cfg.wandering, y_band, 0.5 * cfg.lane_width))
    if np.isnan(tau_c) or np.isnan(tau_p):
        return np.inf  # no crossing: not buildable, the evaluation decides
    if np.isnan(tau_e):
        return 0.0  # the box never reaches the ego's band
    v_e = _speed(tau_c, p_a1, p_a2, p_a3, p_v0, c0) + dv
    if not v_e > 0.0:
        return np.inf
    t_b = tau_p + T_MARGIN + cfg.reaction
    rel = _Relaxed(tau_c, _dist(tau_c, p_a1, p_a2, p_a3, p_v0, c0),
                   _dist(2.0 * p_t, p_a1, p_a2, p_a3, p_v0, c0), 1.0 - math.cos(psi_max),
                   gap - extent, p_a1, p_a2, p_a3, p_v0, c0)
    return _tight_bound(rel, v_e, t_b, tau_e, p_t, after)


@numba.njit(cache=True, nogil=True)
def _bound_kernel(arr: FloatArray, lane_width: float, wandering: float, reaction: float,
                  ehw: float, chl: float, chw: float, stop_at: float,
                  one_minus_cos: FloatArray, out: FloatArray) -> None:  # pragma: no cover
    cfg = _Setup(lane_width, wandering, reaction, ehw, chl, chw, stop_at)
    for r in range(arr.shape[0]):
        out[r] = _bound_row(arr[r], cfg, one_minus_cos)


@numba.njit(cache=True, nogil=True)
def _speed(tau: float, p_a1: float, p_a2: float, p_a3: float, p_v0: float,
           c0: float) -> float:  # pragma: no cover - compiled
    return p_v0 + p_a1 * (min(max(tau - p_a2, 0.0), p_a3) - c0)


def a_req_bound(params: FloatArray, lane_width: float, *, stop_at: float = 0.0,
                settings: CriticalitySettings | None = None) -> FloatArray:
    """An upper bound of ``a_req`` in m/s² for many vectors (module docstring).

    Parameters
    ----------
    params : ndarray of shape (n, 8)
        ``PARAM_NAMES`` order, SI units.
    lane_width : float
        Lane width in m.
    stop_at : float
        Only whether the bound reaches this matters to the caller (m/s²): a row whose
        cheaper, looser bound (from the speeds alone, then with the lateral moments
        bracketed in closed form) stays below it keeps that bound, still >= ``a_req``.
        0: the tight bound everywhere.
    settings : CriticalitySettings, optional
        The criticality's settings (default when None): wandering zone, reaction time.
        The lateral motion is integrated on the kinematics kernel's default grid, which
        ``T_MARGIN`` was chosen for.

    Returns
    -------
    ndarray of shape (n,)
        ``>= a_req`` of every buildable row; +inf where nothing is proved.
    """
    arr = jit.kernel_input(params)  # one compiled version whoever calls
    if arr.ndim != 2 or arr.shape[1] != 8:
        raise SamplerError(f"params: expected shape (n, 8), got {arr.shape}", field="params",
                           problem="wrong shape", value=arr.shape)
    s = settings or CriticalitySettings()
    (_, ew), (cl, cw) = DEFAULT_VEHICLE_SIZE, DEFAULT_VEHICLE_SIZE
    out = np.empty(arr.shape[0])
    _bound_kernel(arr, float(lane_width), float(s.wandering_zone), float(s.reaction_time),
                  0.5 * ew, 0.5 * cl, 0.5 * cw, float(stop_at), _one_minus_cos(DEFAULT_N_GRID),
                  out)
    return out


def btn_bound(params: FloatArray, lane_width: float, *, stop_at: float = 0.0,
              settings: CriticalitySettings | None = None) -> FloatArray:
    """``a_req_bound / decel_max``: an upper bound of ``btn`` (``stop_at`` in btn units)."""
    s = settings or CriticalitySettings()
    return a_req_bound(params, lane_width, stop_at=stop_at * s.decel_max,
                       settings=s) / s.decel_max
