"""Many parameter vectors -> the scripted world of a closed-loop batch, without building
one concrete scenario per vector.

``cutin_tracks(params, ...)`` gives, for N vectors on one time grid, the cutter's track
(centre, heading, speed, acceleration), the ego's start speed, the perception and
crossing moments and the end of the cutter's script: the same numbers
:func:`sampler.scenario.builder.build_scenario` puts into each scenario (equal to about
1e-12 m; tested to 1e-9 m). ``cutin_batch`` wraps them in ``riskcore.sut.CutInBatch``,
the closed-loop simulator's input.

How: one compiled loop over the vectors doing what the builder does per vector
(``datasets.cutin_model.CutInTrajectory``): the lateral motion integrated by composite
4-point Gauss-Legendre quadrature on the same panels (at most 0.1 s, the pulse edges among
their edges) and from the panel edge before each time asked for, the exact integral of the
piecewise-linear speed outside it, the crossing moment by the same root finder, the
cutter placed so that the gap at the crossing is ``gap``. After its
script ends (``t_end``: the lane change and the acceleration pulse are over) the cutter
drives straight at constant speed, exactly as the builder's formulas continue.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from datasets import DEFAULT_LANE_WIDTH, GL_NODES, GL_WEIGHTS, PANEL
from riskcore import jit
from riskcore.sut import CutInBatch
from sampler.errors import BuilderError
from sampler.scenario.builder import (
    DEFAULT_DT,
    DEFAULT_HORIZON,
    DEFAULT_LEAD_IN,
    DEFAULT_VEHICLE_SIZE,
    MAX_DURATION,
)

jit.register(__file__)  # before the first @njit: one cache per version of the kernels

__all__ = ["GRID_BIN", "CutInTracks", "buildable_batch", "buildable_batches", "cutin_batch",
           "cutin_tracks", "own_grid_steps", "reasons"]

FloatArray = NDArray[np.float64]

#: the previous rule's integration step of the lateral motion, s (``quadrature="trapezoid"``)
SUBSTEP = 1e-3
_GL_NODES = np.array(GL_NODES)
_GL_WEIGHTS = np.array(GL_WEIGHTS)
#: ``quadrature`` -> kernel switch
_QUADRATURES = {"gauss": 0, "trapezoid": 1}
#: ``buildable_batches``: a row's own grid ends at its script's end plus the risk horizon,
#: rounded up to a whole multiple of this, s (rows whose grids end alike share a batch)
GRID_BIN = 5.0
#: UN R157's wandering zone: t_p is when the cutter's centre has moved this far, m
WANDERING_ZONE = 0.375

#: kernel status codes
_OK, _NOT_FINITE, _BAD_PT, _BAD_A3, _NO_YAW, _TOO_LONG, _NO_CROSS, _EGO_SPEED, _NEG_SPEED = \
    range(9)
_REASONS = {
    _NOT_FINITE: "a parameter is not finite",
    _BAD_PT: "p_t must be > 0 s",
    _BAD_A3: "p_a3 must be >= 0 s",
    _NO_YAW: "p_y1 is 0, the cutter would not change lanes",
    _TOO_LONG: f"the lane change and pulse last longer than {MAX_DURATION:.0f} s",
    _NO_CROSS: "the lateral motion never reaches the lane marking",
    _EGO_SPEED: "the ego speed v_cutter(t_cross) + dv is not positive",
    _NEG_SPEED: "the cutter's speed becomes negative within the grid",
}


class CutInTracks(NamedTuple):
    """The scripted world of N cut-ins on one grid (shapes (T,), (N,) or (N, T))."""

    t: FloatArray
    ego_v0: FloatArray
    cx: FloatArray
    cy: FloatArray
    cpsi: FloatArray
    cv: FloatArray
    ca: FloatArray
    c_yaw_rate: FloatArray
    t_p: FloatArray
    t_cross: FloatArray
    t_end: FloatArray
    ok: NDArray[np.bool_]
    status: NDArray[np.int64]


class _Script(NamedTuple):
    """One vector's script in the model's time tau (s; 0: the lane change starts)."""

    p_y1: float  # peak yaw rate, rad/s
    p_t: float  # half the lane change's duration, s
    p_a1: float  # the pulse's acceleration, m/s^2
    p_a2: float  # its start, s
    p_a3: float  # its duration, s
    p_v0: float  # speed at tau = 0, m/s
    amp: float  # the heading's amplitude p_y1 * p_t / pi, rad
    end: float  # the lane change's end 2 p_t, s


class _Path(NamedTuple):
    """The cutter's displacement from tau = 0 (x, y) at the quadrature's panel edges."""

    grid: FloatArray
    xs: FloatArray
    ys: FloatArray


class _Track(NamedTuple):
    """One row of the track arrays: centre, heading, speed, acceleration, yaw rate."""

    cx: FloatArray
    cy: FloatArray
    cpsi: FloatArray
    cv: FloatArray
    ca: FloatArray
    cw: FloatArray


class _Scene(NamedTuple):
    """What every row of a batch shares: the script's start on the scenario's clock (s),
    the lane width, the ego's and the cutter's lengths and the wandering zone (m)."""

    lead_in: float
    lane_width: float
    ego_len: float
    cut_len: float
    wz: float


class _Placement(NamedTuple):
    """Where the script sits in the scenario: its start on the scenario's clock and the
    cutter's start (x at tau = 0, y of its own lane's centre)."""

    lead_in: float
    x0: float
    y0: float


@numba.njit(cache=True)
def _speed(t: float, p_a1: float, p_a2: float, p_a3: float, p_v0: float
           ) -> float:  # pragma: no cover - jit
    """The speed profile at t: v0, then the pulse's constant acceleration p_a1 over
    [p_a2, p_a2 + p_a3] (the part before t = 0 taken off, so v(0) = v0)."""
    c = min(max(t - p_a2, 0.0), p_a3)
    c0 = min(max(-p_a2, 0.0), p_a3)
    return p_v0 + p_a1 * (c - c0)


@numba.njit(cache=True)
def _pulse_integral(t: float, p_a1: float, p_a2: float, p_a3: float, p_v0: float
                    ) -> float:  # pragma: no cover - jit
    """``int_0^t`` of :func:`_speed` in closed form (negative for t < 0)."""
    u = min(max(t - p_a2, 0.0), p_a3)
    ht = 0.5 * u * u + p_a3 * max(t - p_a2 - p_a3, 0.0)
    u0 = min(max(0.0 - p_a2, 0.0), p_a3)
    h0 = 0.5 * u0 * u0 + p_a3 * max(0.0 - p_a2 - p_a3, 0.0)
    c0 = min(max(-p_a2, 0.0), p_a3)
    return p_v0 * t + p_a1 * (ht - h0 - c0 * t)


@numba.njit(cache=True)
def _v(tau: float, sc: _Script) -> float:  # pragma: no cover - jit
    """The cutter's speed at tau."""
    return _speed(tau, sc.p_a1, sc.p_a2, sc.p_a3, sc.p_v0)


@numba.njit(cache=True)
def _s(tau: float, sc: _Script) -> float:  # pragma: no cover - jit
    """The distance the speed profile covers from 0 to tau (straight, no heading)."""
    return _pulse_integral(tau, sc.p_a1, sc.p_a2, sc.p_a3, sc.p_v0)


@numba.njit(cache=True)
def _psi(tau: float, sc: _Script) -> float:  # pragma: no cover - jit
    """The cutter's heading at tau inside the lane change."""
    return sc.amp * (1.0 - math.cos(math.pi * tau / sc.p_t))


@numba.njit(cache=True)
def _interp(x: float, xp: FloatArray, fp: FloatArray) -> float:  # pragma: no cover - jit
    """numpy.interp for one x inside [xp[0], xp[-1]] (the same arithmetic)."""
    n = xp.shape[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    if x <= xp[0]:
        return fp[0]
    return _interp_at(x, xp, fp, int(np.searchsorted(xp, x, side="right") - 1))


@numba.njit(cache=True)
def _interp_at(x: float, xp: FloatArray, fp: FloatArray, j: int
               ) -> float:  # pragma: no cover - jit
    """:func:`_interp` for ``xp[0] < x < xp[-1]`` given ``j``, the last index with
    ``xp[j] <= x`` (what its binary search finds)."""
    return _lerp(x, xp[j], xp[j + 1], fp[j], fp[j + 1])


@numba.njit(cache=True)
def _lerp(x: float, xa: float, xb: float, fa: float, fb: float) -> float:  # pragma: no cover
    """numpy.interp's arithmetic between the points (xa, fa) and (xb, fb)."""
    slope = (fb - fa) / (xb - xa)
    r = slope * (x - xa) + fa
    if r != r:
        r = slope * (x - xb) + fb
    return r


@numba.njit(cache=True)
def _gl(a: float, b: float, sc: _Script) -> tuple[float, float]:  # pragma: no cover - jit
    """``int_a^b v cos psi``, ``int_a^b v sin psi``: 4-point Gauss-Legendre on one panel
    (no pulse edge inside; ``datasets.cutin_model._gl``, the same arithmetic)."""
    mid = 0.5 * (a + b)
    half = 0.5 * (b - a)
    sx = 0.0
    sy = 0.0
    for q in range(4):
        s = mid + half * _GL_NODES[q]
        v = _v(s, sc)
        psi = _psi(s, sc)
        sx = sx + _GL_WEIGHTS[q] * (v * math.cos(psi))
        sy = sy + _GL_WEIGHTS[q] * (v * math.sin(psi))
    return half * sx, half * sy


@numba.njit(cache=True)
def _root(a: float, b: float, y_a: float, y_b: float, offset: float,
          sc: _Script) -> float:  # pragma: no cover - jit
    """``datasets.cutin_model.crossing_root``: |y(t)| = offset inside the panel [a, b]."""
    lo = a
    hi = b
    ya = abs(y_a)
    yb = abs(y_b)
    tau = a + (b - a) * (offset - ya) / (yb - ya)
    for _ in range(60):
        dy = _gl(a, tau, sc)[1]
        g = abs(y_a + dy) - offset
        if g == 0.0:
            break
        if g < 0.0:
            lo = tau
        else:
            hi = tau
        d = abs(_v(tau, sc) * math.sin(_psi(tau, sc)))
        nt = tau - g / d if d > 0.0 else math.nan
        if not lo < nt < hi:
            nt = 0.5 * (lo + hi)
        if abs(nt - tau) <= 1e-15 * max(1.0, abs(tau)) or hi - lo <= 1e-15 * max(1.0, hi):
            tau = nt
            break
        tau = nt
    return tau


@numba.njit(cache=True)
def _trapezoid(grid: FloatArray, sc: _Script, xs: FloatArray,
               ys: FloatArray) -> None:  # pragma: no cover - jit
    """The previous rule: x, y at the points of ``grid`` by the composite trapezoid."""
    v_prev = _v(grid[0], sc)
    psi_prev = _psi(grid[0], sc)
    vc_prev = v_prev * math.cos(psi_prev)
    vs_prev = v_prev * math.sin(psi_prev)
    ax = 0.0
    ay = 0.0
    for i in range(1, grid.shape[0]):
        v = _v(grid[i], sc)
        psi = _psi(grid[i], sc)
        vc = v * math.cos(psi)
        vs = v * math.sin(psi)
        h = grid[i] - grid[i - 1]
        ax += 0.5 * (vc + vc_prev) * h
        ay += 0.5 * (vs + vs_prev) * h
        xs[i] = ax
        ys[i] = ay
        vc_prev = vc
        vs_prev = vs


@numba.njit(cache=True)
def _check(row: FloatArray, lead_in: float) -> tuple[int, float]:  # pragma: no cover
    """The builder's refusals before any integration: (status, t_settle), t_settle the
    end of the cutter's script on the scenario's clock."""
    for j in range(8):
        if not math.isfinite(row[j]):
            return _NOT_FINITE, math.nan
    p_y1, p_t, p_a2, p_a3 = row[0], row[1], row[3], row[4]
    if p_t <= 0.0:
        return _BAD_PT, math.nan
    if p_a3 < 0.0:
        return _BAD_A3, math.nan
    if p_y1 == 0.0:
        return _NO_YAW, math.nan
    pulse_end = p_a2 + p_a3 if p_a3 > 0 else 0.0
    t_settle = lead_in + max(2.0 * p_t, pulse_end, 0.0)
    if t_settle > MAX_DURATION:
        return _TOO_LONG, math.nan
    return _OK, t_settle


@numba.njit(cache=True)
def _script(row: FloatArray) -> _Script:  # pragma: no cover - jit
    """The lateral and longitudinal script of a row :func:`_check` accepts."""
    p_y1, p_t = row[0], row[1]
    return _Script(p_y1, p_t, row[2], row[3], row[4], row[5], p_y1 * p_t / math.pi,
                   2.0 * p_t)


@numba.njit(cache=True)
def _uniform_edges(sc: _Script, method: int) -> FloatArray:  # pragma: no cover - jit
    """A uniform grid over [0, end] of panels at most ``PANEL`` wide (narrower for short
    or sharp lane changes; ``SUBSTEP`` for ``method`` 1), its last point exactly end."""
    width = SUBSTEP if method == 1 else min(PANEL, sc.p_t / 8.0, 0.25 / abs(sc.p_y1))
    n_sub = max(math.ceil(sc.end / width), 1)
    step = sc.end / n_sub
    base = np.empty(n_sub + 1)
    for i in range(n_sub + 1):
        base[i] = i * step
    base[n_sub] = sc.end
    return base


@numba.njit(cache=True)
def _pulse_edges(base: FloatArray, sc: _Script) -> FloatArray:  # pragma: no cover - jit
    """The pulse's edges strictly inside (0, end) that ``base`` lacks, ascending, once."""
    e1 = sc.p_a2
    e2 = sc.p_a2 + sc.p_a3
    lo_e = min(e1, e2)
    hi_e = max(e1, e2)
    extra = np.empty(2)
    m = 0
    for e in (lo_e, hi_e):
        if not (0.0 < e < sc.end):
            continue
        if m > 0 and extra[m - 1] == e:
            continue
        k = np.searchsorted(base, e)
        if k < base.shape[0] and base[k] == e:
            continue
        extra[m] = e
        m += 1
    return extra[:m]


@numba.njit(cache=True)
def _panel_edges(sc: _Script, method: int) -> FloatArray:  # pragma: no cover - jit
    """The quadrature's panel edges: :func:`_uniform_edges` merged with
    :func:`_pulse_edges` (``datasets.cutin_model.CutInTrajectory``, the same arithmetic)."""
    base = _uniform_edges(sc, method)
    extra = _pulse_edges(base, sc)
    m = extra.shape[0]
    grid = np.empty(base.shape[0] + m)
    gi = 0
    ei = 0
    for i in range(base.shape[0]):
        while ei < m and extra[ei] < base[i]:
            grid[gi] = extra[ei]
            gi += 1
            ei += 1
        grid[gi] = base[i]
        gi += 1
    while ei < m:
        grid[gi] = extra[ei]
        gi += 1
        ei += 1
    return grid


@numba.njit(cache=True)
def _integrate(grid: FloatArray, sc: _Script, method: int) -> _Path:  # pragma: no cover
    """The lateral motion integrated panel by panel (Gauss-Legendre; ``method`` 1: the
    composite trapezoid) from (0, 0) at tau = 0."""
    ng = grid.shape[0]
    xs = np.empty(ng)
    ys = np.empty(ng)
    xs[0] = 0.0
    ys[0] = 0.0
    if method == 1:
        _trapezoid(grid, sc, xs, ys)
    else:
        for i in range(1, ng):
            dx, dy = _gl(grid[i - 1], grid[i], sc)
            xs[i] = xs[i - 1] + dx
            ys[i] = ys[i - 1] + dy
    return _Path(grid, xs, ys)


@numba.njit(cache=True)
def _crossing(path: _Path, offset: float, sc: _Script,
              method: int) -> tuple[bool, float, float]:  # pragma: no cover - jit
    """(found, tau_c, x there): the first edge with |y| >= offset, then the root inside
    that panel (``method`` 1: linear between the edges)."""
    grid, xs, ys = path
    ic = -1
    for i in range(grid.shape[0]):
        if abs(ys[i]) >= offset:
            ic = i
            break
    if ic < 0:
        return False, math.nan, math.nan
    if ic == 0:
        return True, 0.0, 0.0
    if method == 1:
        y0 = abs(ys[ic - 1])
        frac = (offset - y0) / (abs(ys[ic]) - y0)
        tau_c = grid[ic - 1] + frac * (grid[ic] - grid[ic - 1])
        return True, tau_c, _interp(tau_c, grid, xs)
    tau_c = _root(grid[ic - 1], grid[ic], ys[ic - 1], ys[ic], offset, sc)
    return True, tau_c, xs[ic - 1] + _gl(grid[ic - 1], tau_c, sc)[0]


@numba.njit(cache=True)
def _outside(tau: float, sc: _Script, g_first: float, g_last: float, x_first: float,
             y_first: float, x_last: float, y_last: float
             ) -> tuple[float, float]:  # pragma: no cover - jit
    """The displacement (x, y) at a tau outside the path's open interval (``g_first``,
    ``g_last``) (:func:`_inside`): before the script straight, after the lane change
    straight on from its end, at an end of the path its value there."""
    if tau < 0.0:
        return _s(tau, sc), y_first
    if tau > sc.end:
        return x_last + (_s(tau, sc) - _s(sc.end, sc)), y_last
    if tau >= g_last:
        return x_last, y_last
    return x_first, y_first


@numba.njit(cache=True)
def _within(tau: float, sc: _Script, g0: float, g1: float, x0: float, x1: float, y0: float,
            y1: float, method: int) -> tuple[float, float]:  # pragma: no cover - jit
    """The displacement (x, y) at tau inside the panel [g0, g1] whose edges are at (x0,
    y0) and (x1, y1): from g0 by Gauss-Legendre (``method`` 1: linear)."""
    if method == 1:
        return _lerp(tau, g0, g1, x0, x1), _lerp(tau, g0, g1, y0, y1)
    dx, dy = _gl(g0, tau, sc)
    return x0 + dx, y0 + dy


@numba.njit(cache=True)
def _fill(t: FloatArray, path: _Path, sc: _Script, place: _Placement, track: _Track,
          method: int) -> bool:  # pragma: no cover - jit
    """The cutter's track at the times ``t``; False (the track cut short) when its speed
    becomes negative within them. The path's panel of each time is found walking on from
    the previous one (the times increase). Only scalars go to the helpers inside the
    loop: a compiled call taking an array increments and decrements its reference count
    (two atomic operations), which cost a fifth of the builder's time when the path's
    arrays went to a helper at every time."""
    grid, xs, ys = path
    cx, cy, cpsi, cv, ca, cw = track
    last = grid.shape[0] - 1
    jg = 0
    for k in range(t.shape[0]):
        tau = t[k] - place.lead_in
        if tau < 0.0 or tau > sc.end or tau >= grid[last] or tau <= grid[0]:
            xr, yr = _outside(tau, sc, grid[0], grid[last], xs[0], ys[0], xs[last],
                              ys[last])
        else:
            while grid[jg + 1] <= tau:
                jg += 1
            xr, yr = _within(tau, sc, grid[jg], grid[jg + 1], xs[jg], xs[jg + 1], ys[jg],
                             ys[jg + 1], method)
        v = _v(tau, sc)
        if v < 0.0:
            return False
        cx[k] = place.x0 + xr
        cy[k] = place.y0 + yr
        if 0.0 <= tau <= sc.end:
            cpsi[k] = _psi(tau, sc)
            cw[k] = sc.p_y1 * math.sin(math.pi * tau / sc.p_t)
        else:
            cpsi[k] = 0.0
            cw[k] = 0.0
        cv[k] = v
        ca[k] = sc.p_a1 if (sc.p_a2 <= tau < sc.p_a2 + sc.p_a3) else 0.0
    return True


@numba.njit(cache=True)
def _perception(t: FloatArray, cy: FloatArray, wz: float) -> float:  # pragma: no cover
    """t_p: the centre has moved wz towards the ego (riskcore.criticality's rule, on the
    samples, linear between them); NaN if it never does within ``t``."""
    toward = 1.0 if (0.0 - cy[0]) >= 0.0 else -1.0
    prev = 0.0
    for k in range(t.shape[0]):
        mv = (cy[k] - cy[0]) * toward
        if mv >= wz:
            if k == 0:
                return t[0]
            f = (wz - prev) / (mv - prev)
            return t[k - 1] + f * (t[k] - t[k - 1])
        prev = mv
    return math.nan


@numba.njit(cache=True)
def _one(row: FloatArray, t: FloatArray, scene: _Scene, track: _Track, method: int
         ) -> tuple[int, float, float, float, float]:  # pragma: no cover - jit
    """One vector: fills the cutter's row; returns (status, v_ego, t_cross, t_p, t_end).
    ``method`` 1: the previous rule (the composite trapezoid on a 1 ms grid, the pulse
    edges inserted, linear interpolation between its points and for the crossing)."""
    nan = math.nan
    lead_in, lane_width = scene.lead_in, scene.lane_width
    status, t_settle = _check(row, lead_in)
    if status != _OK:
        return status, nan, nan, nan, nan
    sc = _script(row)
    path = _integrate(_panel_edges(sc, method), sc, method)
    found, tau_c, x_rel_c = _crossing(path, lane_width / 2.0, sc, method)
    if not found:
        return _NO_CROSS, nan, nan, nan, nan
    v_ego = _v(tau_c, sc) + row[6]
    if not v_ego > 0:
        return _EGO_SPEED, nan, nan, nan, nan
    t_c = lead_in + tau_c
    x_cut0 = row[7] + 0.5 * (scene.cut_len + scene.ego_len) + v_ego * t_c - x_rel_c
    y_start = -lane_width if sc.p_y1 > 0 else lane_width
    if not _fill(t, path, sc, _Placement(lead_in, x_cut0, y_start), track, method):
        return _NEG_SPEED, nan, nan, nan, nan
    return _OK, v_ego, t_c, _perception(t, track.cy, scene.wz), t_settle


@numba.njit(cache=True)
def _all(params: FloatArray, t: FloatArray, scene: _Scene, tracks: _Track,
         status: NDArray[np.int64], out: FloatArray,
         compact: bool, method: int) -> None:  # pragma: no cover - jit
    """Every row; the tracks of row i in row i of the (N, T) ``tracks`` or, ``compact``,
    those of the buildable rows one after another (a refused row's slot is reused).
    ``method`` 1: the previous rule (:func:`_one`)."""
    cx, cy, cpsi, cv, ca, cw = tracks
    j = 0
    for i in range(params.shape[0]):
        r = j if compact else i
        track = _Track(cx[r], cy[r], cpsi[r], cv[r], ca[r], cw[r])
        s, v_ego, t_c, t_p, t_end = _one(params[i], t, scene, track, method)
        status[i] = s
        out[i, 0] = v_ego
        out[i, 1] = t_c
        out[i, 2] = t_p
        out[i, 3] = t_end
        if s == _OK:
            j += 1


@numba.njit(cache=True)
def _repack(flat: FloatArray, k: int, width: int, m: int) -> None:  # pragma: no cover
    """Rows 0..k-1 of a C-ordered (., width) buffer cut to their first m values, stored
    as a C-ordered (k, m) array at the buffer's start (in place, forwards: m <= width)."""
    for i in range(1, k):
        src = i * width
        dst = i * m
        for q in range(m):
            flat[dst + q] = flat[src + q]


def _cut_rows(a: FloatArray, k: int, m: int) -> FloatArray:
    """The first k rows of ``a`` (C-ordered), each cut to its first m values, as a
    C-contiguous (k, m) view of ``a``'s buffer (``a`` is overwritten)."""
    width = a.shape[1]
    flat = a.reshape(-1)
    if m < width:
        _repack(flat, k, width, m)
    return flat[:k * m].reshape(k, m)


def _time_grid(n_steps: int, dt: float) -> FloatArray:
    return np.round(np.arange(n_steps + 1, dtype=np.float64) * dt, 12)


def _grid_steps(x: FloatArray, dt: float, lead_in: float, duration: float | None) -> int:
    """The number of steps of ``cutin_tracks``'s grid for the rows ``x`` (its docstring)."""
    if duration is None:
        with np.errstate(invalid="ignore"):
            pulse_end = np.where(x[:, 4] > 0, x[:, 3] + x[:, 4], 0.0)
            settle = lead_in + np.maximum(np.maximum(2.0 * x[:, 1], pulse_end), 0.0)
        good = np.isfinite(settle) & (settle <= MAX_DURATION)
        longest = float(settle[good].max()) if good.any() else lead_in
        duration = longest + DEFAULT_HORIZON
    duration = _positive(duration, "duration")
    n_steps = max(math.ceil(duration / dt - 1e-9), 1)
    if n_steps > 100_000:
        raise BuilderError(f"duration: {duration} s is more than 100000 steps of {dt} s",
                           field="duration")
    return n_steps


def _positive(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating
                                                  | np.integer):
        raise BuilderError(f"{name}: expected a number, got {value!r}", field=name)
    x = float(value)
    if not (math.isfinite(x) and x > 0):
        raise BuilderError(f"{name}: must be a positive finite number, got {value!r}",
                           field=name)
    return x


def cutin_tracks(params: Any, *, lane_width: float = DEFAULT_LANE_WIDTH,
                 ego_length: float = DEFAULT_VEHICLE_SIZE[0],
                 cutter_length: float = DEFAULT_VEHICLE_SIZE[0], dt: float = DEFAULT_DT,
                 lead_in: float = DEFAULT_LEAD_IN, duration: float | None = None,
                 wandering_zone: float = WANDERING_ZONE,
                 quadrature: str = "gauss") -> CutInTracks:
    """The builder's tracks of N vectors (N, 8) in ``PARAM_NAMES`` order on one grid.

    ``duration`` (s): the grid's end; default the latest end of a valid row's script plus
    the risk horizon (3 s), in whole steps. Rows the builder would refuse get ``ok``
    False, their ``status`` code (``reasons``) and NaN or zero tracks; nothing raises.
    ``quadrature``: "gauss" (the builder's rule, module docstring) or "trapezoid" (the
    previous rule: composite trapezoid on 1 ms, linear between its points; kept as the
    reference of the accuracy tests and the benchmark's baseline).
    """
    _, t, status, out, (cx, cy, cpsi, cv, ca, cw) = _build(
        params, lane_width, ego_length, cutter_length, dt, lead_in, duration,
        wandering_zone, compact=False, quadrature=quadrature)
    ok = status == _OK
    return CutInTracks(t=t, ego_v0=out[:, 0], cx=cx, cy=cy, cpsi=cpsi, cv=cv, ca=ca,
                       c_yaw_rate=cw, t_p=out[:, 2], t_cross=out[:, 1], t_end=out[:, 3], ok=ok,
                       status=status)


def _build(params: Any, lane_width: float, ego_length: float, cutter_length: float,
           dt: float, lead_in: float, duration: float | None, wandering_zone: float,
           compact: bool, quadrature: str = "gauss"
           ) -> tuple[FloatArray, FloatArray, NDArray[np.int64], FloatArray,
                      tuple[FloatArray, ...]]:
    """(params, t, status, the (N, 4) v_ego / t_cross / t_p / t_end, the six (N, T) track
    arrays: row i's or, ``compact``, the buildable rows' one after another)."""
    x = jit.kernel_input(np.atleast_2d(np.asarray(params, dtype=np.float64)))
    if x.ndim != 2 or x.shape[1] != 8:
        raise BuilderError(f"params: expected shape (N, 8), got {x.shape}", field="params")
    if quadrature not in _QUADRATURES:
        raise BuilderError(f"quadrature: expected one of {sorted(_QUADRATURES)}, got "
                           f"{quadrature!r}", field="quadrature")
    dt = _positive(dt, "dt")
    lane_width = _positive(lane_width, "lane_width")
    ego_length = _positive(ego_length, "ego_length")
    cutter_length = _positive(cutter_length, "cutter_length")
    if isinstance(lead_in, bool) or not (float(lead_in) >= 0 and math.isfinite(lead_in)):
        raise BuilderError(f"lead_in: must be a finite number >= 0 s, got {lead_in!r}",
                           field="lead_in")
    n = x.shape[0]
    n_steps = _grid_steps(x, dt, float(lead_in), duration)
    t = _time_grid(n_steps, dt)
    shape = (n, t.shape[0])
    alloc = np.empty if compact else np.zeros
    cx, cy, cpsi, cv, ca, cw = (alloc(shape) for _ in range(6))
    status = np.zeros(n, dtype=np.int64)
    out = np.full((n, 4), np.nan)
    scene = _Scene(float(lead_in), lane_width, ego_length, cutter_length,
                   float(wandering_zone))
    _all(x, t, scene, _Track(cx, cy, cpsi, cv, ca, cw), status, out, compact,
         _QUADRATURES[quadrature])
    return x, t, status, out, (cx, cy, cpsi, cv, ca, cw)


def reasons(status: NDArray[np.int64]) -> list[str | None]:
    """Why each row is not a buildable cut-in (None: it is)."""
    return [_REASONS.get(int(s)) for s in status]


def cutin_batch(params: Any, *, lane_width: float = DEFAULT_LANE_WIDTH,
                ego_length: float = DEFAULT_VEHICLE_SIZE[0],
                ego_width: float = DEFAULT_VEHICLE_SIZE[1],
                cutter_length: float = DEFAULT_VEHICLE_SIZE[0],
                cutter_width: float = DEFAULT_VEHICLE_SIZE[1], dt: float = DEFAULT_DT,
                lead_in: float = DEFAULT_LEAD_IN, duration: float | None = None,
                wandering_zone: float = WANDERING_ZONE,
                quadrature: str = "gauss") -> CutInBatch:
    """``riskcore.sut.CutInBatch`` of N vectors (N, 8): the builder's tracks (module
    docstring). A row the builder would refuse is an error naming the row and why
    (``cutin_tracks`` reports them instead)."""
    tr = cutin_tracks(params, lane_width=lane_width, ego_length=ego_length,
                      cutter_length=cutter_length, dt=dt, lead_in=lead_in, duration=duration,
                      wandering_zone=wandering_zone, quadrature=quadrature)
    bad = np.flatnonzero(~tr.ok)
    if bad.size:
        i = int(bad[0])
        raise BuilderError(f"params[{i}]: {reasons(tr.status[i:i + 1])[0]} "
                           f"({bad.size} row(s) refused)", field=f"params[{i}]")
    return CutInBatch(t=tr.t, lane_width=float(lane_width), ego_v0=tr.ego_v0,
                      ego_length=float(ego_length), ego_width=float(ego_width), cx=tr.cx,
                      cy=tr.cy, cpsi=tr.cpsi, cv=tr.cv, ca=tr.ca,
                      c_length=np.full(tr.ego_v0.shape[0], float(cutter_length)),
                      c_width=np.full(tr.ego_v0.shape[0], float(cutter_width)),
                      t_p=tr.t_p, t_cross=tr.t_cross, t_end=tr.t_end,
                      c_yaw_rate=tr.c_yaw_rate)


def buildable_batch(params: Any, *, lane_width: float = DEFAULT_LANE_WIDTH,
                    ego_length: float = DEFAULT_VEHICLE_SIZE[0],
                    ego_width: float = DEFAULT_VEHICLE_SIZE[1],
                    cutter_length: float = DEFAULT_VEHICLE_SIZE[0],
                    cutter_width: float = DEFAULT_VEHICLE_SIZE[1], dt: float = DEFAULT_DT,
                    lead_in: float = DEFAULT_LEAD_IN, duration: float | None = None,
                    wandering_zone: float = WANDERING_ZONE, quadrature: str = "gauss"
                    ) -> tuple[NDArray[np.int64], NDArray[np.intp], CutInBatch | None]:
    """Every row's ``status`` (``cutin_tracks``'s; ``reasons``), the buildable rows
    ``rows`` and their batch, equal to ``cutin_batch(params[rows], same keywords)`` array
    for array (None when no row is buildable), building each row's tracks once.

    The batch's grid is that of ``cutin_batch(params[rows])`` (by default it ends at the
    buildable rows' latest script end plus the risk horizon; ``cutin_tracks`` also counts
    rows refused after that end is known, so its grid can be longer): the tracks are cut to
    it. Every grid value of a row depends on its time only, and a row's ``t_p`` lies
    before its script's end, so the cut tracks are those built on the shorter grid. The
    buildable rows' tracks are written one after another and cut in place: no copy.
    """
    x, t, status, out, arrays = _build(params, lane_width, ego_length, cutter_length, dt,
                                       lead_in, duration, wandering_zone, compact=True,
                                       quadrature=quadrature)
    rows = np.flatnonzero(status == _OK)
    k = rows.size
    if k == 0:
        return status, rows, None
    n = status.shape[0]
    n_steps = _grid_steps(x if k == n else x[rows], float(dt), float(lead_in), duration)
    m = n_steps + 1
    assert m <= t.shape[0]
    cx, cy, cpsi, cv, ca, cw = (_cut_rows(a, k, m) for a in arrays)
    per_row = out if k == n else out[rows]
    batch = CutInBatch(t=t[:m], lane_width=float(lane_width), ego_v0=per_row[:, 0],
                       ego_length=float(ego_length), ego_width=float(ego_width),
                       cx=cx, cy=cy, cpsi=cpsi, cv=cv, ca=ca,
                       c_length=np.full(k, float(cutter_length)),
                       c_width=np.full(k, float(cutter_width)), t_p=per_row[:, 2],
                       t_cross=per_row[:, 1], t_end=per_row[:, 3], c_yaw_rate=cw)
    return status, rows, batch


def own_grid_steps(params: Any, *, dt: float = DEFAULT_DT,
                   lead_in: float = DEFAULT_LEAD_IN) -> NDArray[np.int64]:
    """The number of steps of each row's own grid (``buildable_batches``): its script's
    end (``t_end``: the lane change and the acceleration pulse are over) plus the risk
    horizon (3 s) in whole steps, rounded up to a whole multiple of ``GRID_BIN`` (5 s).
    A function of the row alone. Rows the builder refuses before their end is known
    (a non-finite end, or one past the builder's longest scenario) get the first bin."""
    x = np.atleast_2d(np.asarray(params, dtype=np.float64))
    dt = _positive(dt, "dt")
    with np.errstate(invalid="ignore"):
        pulse_end = np.where(x[:, 4] > 0, x[:, 3] + x[:, 4], 0.0)
        settle = lead_in + np.maximum(np.maximum(2.0 * x[:, 1], pulse_end), 0.0)
    good = np.isfinite(settle) & (settle <= MAX_DURATION)
    end = np.where(good, settle, lead_in) + DEFAULT_HORIZON
    steps = np.maximum(np.ceil(end / dt - 1e-9), 1.0)
    q = max(math.ceil(GRID_BIN / dt - 1e-9), 1)
    return (np.ceil(steps / q) * q).astype(np.int64)


def buildable_batches(params: Any, *, lane_width: float = DEFAULT_LANE_WIDTH,
                      ego_length: float = DEFAULT_VEHICLE_SIZE[0],
                      ego_width: float = DEFAULT_VEHICLE_SIZE[1],
                      cutter_length: float = DEFAULT_VEHICLE_SIZE[0],
                      cutter_width: float = DEFAULT_VEHICLE_SIZE[1], dt: float = DEFAULT_DT,
                      lead_in: float = DEFAULT_LEAD_IN,
                      wandering_zone: float = WANDERING_ZONE, quadrature: str = "gauss"
                      ) -> tuple[NDArray[np.int64], list[tuple[NDArray[np.intp], CutInBatch]]]:
    """Every row's ``status`` and the buildable rows as batches ``(rows, batch)``, each row
    on its own grid (``own_grid_steps``: its script's end plus the risk horizon, rounded
    up to a whole multiple of 5 s); rows with the same grid share a batch, in increasing
    order of the grid's length.

    A row's tracks, and so its simulated outcome, are a function of the row alone: the
    simulator continues the cutter past a batch's grid from the grid's last step, so on
    one grid sized by the longest row of a block (``buildable_batch``) a run outliving its
    own script would depend on which rows share its block. Each batch equals
    ``cutin_batch(params[rows], duration=its grid's end)`` array for array.
    """
    x = jit.kernel_input(np.atleast_2d(np.asarray(params, dtype=np.float64)))
    if x.ndim != 2 or x.shape[1] != 8:
        raise BuilderError(f"params: expected shape (N, 8), got {x.shape}", field="params")
    steps = own_grid_steps(x, dt=dt, lead_in=lead_in)
    status = np.empty(x.shape[0], dtype=np.int64)
    groups: list[tuple[NDArray[np.intp], CutInBatch]] = []
    for m in np.unique(steps):
        idx = np.flatnonzero(steps == m)
        st, local, batch = buildable_batch(
            x[idx], lane_width=lane_width, ego_length=ego_length, ego_width=ego_width,
            cutter_length=cutter_length, cutter_width=cutter_width, dt=dt, lead_in=lead_in,
            duration=int(m) * float(dt), wandering_zone=wandering_zone,
            quadrature=quadrature)
        status[idx] = st
        if batch is not None:
            groups.append((idx[local], batch))
    return status, groups
