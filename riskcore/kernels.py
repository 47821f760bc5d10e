"""Compiled (numba) kernels of the risk engine. Private: use the public modules.

Pose arrays hold ``[x, y, cos ψ, sin ψ]`` in their last axis (m, m, -, -): the overlap
test needs the heading only through its cosine and sine, so they are computed once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from riskcore import jit

jit.register(__file__)  # before the first @njit: one cache per version of the kernels

FloatArray = NDArray[np.float64]

# Below this |φ| = |ω τ| the CTRA integrals use their Taylor series (truncation error of
# the first dropped term < 1e-17; the closed form loses < 1e-12 relative at the switch).
_SERIES_BELOW = 0.1


@njit(cache=True)
def ctra_terms(phi: float) -> tuple[float, float, float, float, float, float]:  # pragma: no cover
    """The four integrals of the CTRA model over u ∈ [0, 1] for φ = ω τ, and sin φ, cos φ.

    S0 = ∫ cos(φu) du = sin φ / φ,          C0 = ∫ sin(φu) du = (1 - cos φ) / φ,
    S1 = ∫ u cos(φu) du = (φ sin φ + cos φ - 1) / φ²,
    C1 = ∫ u sin(φu) du = (sin φ - φ cos φ) / φ².
    For |φ| < 0.1 the Taylor series (to φ⁸ / φ⁹) replace the cancelling closed forms; the
    limits at φ = 0 are S0 = 1, C0 = 0, S1 = 1/2, C1 = 0. There sin φ = φ S0 and
    cos φ = 1 - φ C0. Returns (S0, C0, S1, C1, sin φ, cos φ); odd in φ where the function
    is odd, bit for bit (mirror symmetry).
    """
    if abs(phi) < _SERIES_BELOW:
        p2 = phi * phi
        s0 = 1.0 + p2 * (-1.0 / 6.0 + p2 * (1.0 / 120.0 + p2 * (-1.0 / 5040.0
                                                               + p2 / 362880.0)))
        c0 = phi * (0.5 + p2 * (-1.0 / 24.0 + p2 * (1.0 / 720.0 + p2 * (-1.0 / 40320.0
                                                                        + p2 / 3628800.0))))
        s1 = 0.5 + p2 * (-0.125 + p2 * (1.0 / 144.0 + p2 * (-1.0 / 5760.0 + p2 / 403200.0)))
        c1 = phi * (1.0 / 3.0 + p2 * (-1.0 / 30.0 + p2 * (1.0 / 840.0 + p2 * (
            -1.0 / 45360.0 + p2 / 3991680.0))))
        return s0, c0, s1, c1, phi * s0, 1.0 - phi * c0
    s = math.sin(phi)
    c = math.cos(phi)
    return (s / phi, (1.0 - c) / phi, (phi * s + c - 1.0) / (phi * phi),
            (s - phi * c) / (phi * phi), s, c)


@njit(cache=True)
def ctra_pose_cs(x0: float, y0: float, cp: float, sp: float, v0: float, a: float, w: float,
                 tau: float) -> tuple[float, float, float, float, float, float]:  # pragma: no cover
    """State after ``tau`` s of constant inputs (a, ω), exactly; heading as cos and sin.

    ψ(τ) = ψ0 + ωτ, v(τ) = v0 + aτ and, with φ = ωτ,
    x(τ) = x0 + L cos ψ0 - S sin ψ0, y(τ) = y0 + L sin ψ0 + S cos ψ0,
    L = v0 τ S0(φ) + a τ² S1(φ), S = v0 τ C0(φ) + a τ² C1(φ) (see :func:`ctra_terms`).
    The vehicle does not reverse: with a < 0 it stops at τ_s = v0 / -a and then stays
    (position and heading frozen); at standstill with a ≤ 0 it does not turn on the spot.

    Parameters: initial centre (x0, y0), cos ψ0 = cp, sin ψ0 = sp, speed v0, inputs a, ω,
    elapsed time τ. Returns (x, y, cos ψ, sin ψ, v, φ), φ the heading change in rad.
    """
    if a < 0.0:
        t_stop = v0 / (-a)
        if tau > t_stop:
            tau = t_stop
    elif a == 0.0 and v0 <= 0.0:
        tau = 0.0
    phi = w * tau
    s0, c0, s1, c1, sphi, cphi = ctra_terms(phi)
    lon = v0 * tau * s0 + a * tau * tau * s1
    lat = v0 * tau * c0 + a * tau * tau * c1
    return (x0 + lon * cp - lat * sp, y0 + lon * sp + lat * cp, cp * cphi - sp * sphi,
            sp * cphi + cp * sphi, v0 + a * tau, phi)


@njit(cache=True)
def ctra_pose(x0: float, y0: float, psi0: float, v0: float, a: float, w: float,
              tau: float) -> tuple[float, float, float, float]:  # pragma: no cover - jit
    """:func:`ctra_pose_cs` with the heading as an angle: returns (x, y, ψ, v)."""
    x, y, _, _, v, phi = ctra_pose_cs(x0, y0, math.cos(psi0), math.sin(psi0), v0, a, w, tau)
    return x, y, psi0 + phi, v


@njit(cache=True)
def ctra_many(x0: FloatArray, y0: FloatArray, psi0: FloatArray, v0: FloatArray,
              a: FloatArray, w: FloatArray, tau: FloatArray,
              out: FloatArray) -> None:  # pragma: no cover - jit
    """:func:`ctra_pose` over flat arrays of equal length; ``out`` has shape (n, 4)."""
    for i in range(x0.shape[0]):
        x, y, p, v = ctra_pose(x0[i], y0[i], psi0[i], v0[i], a[i], w[i], tau[i])
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = p
        out[i, 3] = v


@njit(cache=True)
def predict(x0: float, y0: float, psi0: float, v0: float, a: FloatArray, w: FloatArray,
            n_steps: int, dt: float) -> FloatArray:  # pragma: no cover - jit
    """Poses of every input pair over the horizon: shape (n_smp, n_steps + 1, 4).

    Step n is at τ = n · dt from the initial state, with the closed form of
    :func:`ctra_pose_cs`. Where that needs sin φ_n and cos φ_n of φ_n = ω n dt (|φ_n| ≥ 0.1,
    before any stop), they come from the angle-addition recurrence with sin(ω dt) and
    cos(ω dt) instead of two library calls per step (relative error ≲ n · 1e-16; exactly odd
    in ω, so mirror symmetry is kept bit for bit).
    """
    n_smp = a.shape[0]
    out = np.empty((n_smp, n_steps + 1, 4))
    cp = math.cos(psi0)
    sp = math.sin(psi0)
    for i in range(n_smp):
        ai = a[i]
        wi = w[i]
        t_stop = v0 / (-ai) if ai < 0.0 else np.inf
        if ai == 0.0 and v0 <= 0.0:
            t_stop = 0.0
        s1 = math.sin(wi * dt)
        c1 = math.cos(wi * dt)
        sn = 0.0
        cn = 1.0
        for n in range(n_steps + 1):
            tau = n * dt
            if n > 0:
                sn, cn = sn * c1 + cn * s1, cn * c1 - sn * s1
            phi = wi * tau
            if tau > t_stop or abs(phi) < _SERIES_BELOW:
                x, y, c, s, _, _ = ctra_pose_cs(x0, y0, cp, sp, v0, ai, wi, tau)
            else:
                f0 = sn / phi
                g0 = (1.0 - cn) / phi
                f1 = (phi * sn + cn - 1.0) / (phi * phi)
                g1 = (sn - phi * cn) / (phi * phi)
                lon = v0 * tau * f0 + ai * tau * tau * f1
                lat = v0 * tau * g0 + ai * tau * tau * g1
                x = x0 + lon * cp - lat * sp
                y = y0 + lon * sp + lat * cp
                c = cp * cn - sp * sn
                s = sp * cn + cp * sn
            out[i, n, 0] = x
            out[i, n, 1] = y
            out[i, n, 2] = c
            out[i, n, 3] = s
    return out


@njit(cache=True)
def ego_poses(x: FloatArray, y: FloatArray, psi: FloatArray) -> FloatArray:  # pragma: no cover
    """Poses of the ego's known future: shape (n_steps + 1, 4)."""
    out = np.empty((x.shape[0], 4))
    for n in range(x.shape[0]):
        out[n, 0] = x[n]
        out[n, 1] = y[n]
        out[n, 2] = math.cos(psi[n])
        out[n, 3] = math.sin(psi[n])
    return out


@njit(cache=True)
def fill_evasion(ego: FloatArray, v: FloatArray, man_a: FloatArray, man_w: FloatArray,
                 dt: float, j: int, m: int, eva: FloatArray) -> None:  # pragma: no cover
    """The ego's evasive trajectory for reaction step j and manoeuvre m, into ``eva[j, m]``.

    Parameters
    ----------
    ego : ndarray of shape (N + 1, 4)
        The ego's known poses ``[x, y, cos ψ, sin ψ]``.
    v : ndarray of shape (N + 1,)
        The ego's known speeds in m/s.
    man_a, man_w : ndarray of shape (N, M)
        Inputs (m/s², rad/s) of manoeuvre m when started at reaction step j.
    dt : float
    j, m : int
    eva : ndarray of shape (N, M, N + 1, 4)
        ``eva[j, m, n]`` for n > j becomes the pose at step n after leaving the known
        trajectory at step j with manoeuvre m (CTRA from the known state at step j).
    """
    for n in range(j + 1, ego.shape[0]):
        px, py, pc, ps, _, _ = ctra_pose_cs(ego[j, 0], ego[j, 1], ego[j, 2], ego[j, 3], v[j],
                                            man_a[j, m], man_w[j, m], (n - j) * dt)
        eva[j, m, n, 0] = px
        eva[j, m, n, 1] = py
        eva[j, m, n, 2] = pc
        eva[j, m, n, 3] = ps


@njit(cache=True)
def overlap(ax: float, ay: float, ac: float, as_: float, ahl: float, ahw: float, ar: float,
            bx: float, by: float, bc: float, bs: float, bhl: float, bhw: float,
            br: float) -> bool:  # pragma: no cover - jit
    """Do two oriented boxes overlap with positive area? (separating-axis test)

    Box = centre (x, y), heading (cos, sin), half length hl, half width hw, circumradius
    r = hypot(hl, hw). Touching boxes (a shared edge or corner, zero-area contact) do NOT
    overlap: an axis separates when |d · u| ≥ r_A(u) + r_B(u). Broad phase first: circles
    that do not overlap (distance ≥ r_A + r_B) mean no overlap.
    """
    dx = bx - ax
    dy = by - ay
    rr = ar + br
    if dx * dx + dy * dy >= rr * rr:
        return False
    c11 = ac * bc + as_ * bs
    c12 = as_ * bc - ac * bs
    c21 = ac * bs - as_ * bc
    c22 = ac * bc + as_ * bs
    if abs(dx * ac + dy * as_) >= ahl + bhl * abs(c11) + bhw * abs(c12):
        return False
    if abs(dy * ac - dx * as_) >= ahw + bhl * abs(c21) + bhw * abs(c22):
        return False
    if abs(dx * bc + dy * bs) >= bhl + ahl * abs(c11) + ahw * abs(c21):
        return False
    return not abs(dy * bc - dx * bs) >= bhw + ahl * abs(c12) + ahw * abs(c22)


@njit(cache=True)
def overlap_many(a: FloatArray, b: FloatArray) -> NDArray[np.bool_]:  # pragma: no cover
    """Vectorised :func:`overlap`: rows ``[x, y, psi, length, width]``, shapes (n, 5)."""
    n = a.shape[0]
    out = np.empty(n, dtype=np.bool_)
    for i in range(n):
        ahl = 0.5 * a[i, 3]
        ahw = 0.5 * a[i, 4]
        bhl = 0.5 * b[i, 3]
        bhw = 0.5 * b[i, 4]
        out[i] = overlap(a[i, 0], a[i, 1], math.cos(a[i, 2]), math.sin(a[i, 2]), ahl, ahw,
                         math.hypot(ahl, ahw), b[i, 0], b[i, 1], math.cos(b[i, 2]),
                         math.sin(b[i, 2]), bhl, bhw, math.hypot(bhl, bhw))
    return out


@njit(cache=True)
def _avoids(ego: FloatArray, v: FloatArray, man_a: FloatArray, man_w: FloatArray, dt: float,
            eva: FloatArray, done: NDArray[np.bool_], j: int, m: int, traj: FloatArray, i: int,
            c: int, ehl: float, ehw: float, er: float, ohl: float, ohw: float,
            orad: float) -> bool:  # pragma: no cover - jit
    """Does manoeuvre m started at step j stay clear of trajectory i on steps j+1..N?

    The evasive trajectory is computed on first use and kept in ``eva`` (``done[j, m]``),
    for all objects of the scene. Steps c..N are checked first (where the known trajectory
    collided), then j+1..c-1: a failing manoeuvre is usually found at once. The answer does
    not depend on the order.
    """
    if not done[j, m]:
        fill_evasion(ego, v, man_a, man_w, dt, j, m, eva)
        done[j, m] = True
    n_pts = traj.shape[1]
    for n in range(c, n_pts):
        if overlap(eva[j, m, n, 0], eva[j, m, n, 1], eva[j, m, n, 2], eva[j, m, n, 3],
                   ehl, ehw, er, traj[i, n, 0], traj[i, n, 1], traj[i, n, 2], traj[i, n, 3],
                   ohl, ohw, orad):
            return False
    for n in range(j + 1, c):
        if overlap(eva[j, m, n, 0], eva[j, m, n, 1], eva[j, m, n, 2], eva[j, m, n, 3],
                   ehl, ehw, er, traj[i, n, 0], traj[i, n, 1], traj[i, n, 2], traj[i, n, 3],
                   ohl, ohw, orad):
            return False
    return True


@njit(cache=True)
def ttr_scan(traj: FloatArray, ohl: float, ohw: float, ego: FloatArray, v: FloatArray,
             ehl: float, ehw: float, man_a: FloatArray, man_w: FloatArray, dt: float,
             eva: FloatArray, done: NDArray[np.bool_]
             ) -> tuple[NDArray[np.int64], NDArray[np.int64],
                        NDArray[np.int64]]:  # pragma: no cover - jit
    """First collision, reaction step and evasion mask of every predicted trajectory.

    Parameters
    ----------
    traj : ndarray of shape (S, N + 1, 4)
        The object's predicted poses.
    ohl, ohw : float
        The object's half length and half width in m.
    ego : ndarray of shape (N + 1, 4)
        The ego's known poses.
    v : ndarray of shape (N + 1,)
        The ego's known speeds in m/s.
    ehl, ehw : float
        The ego's half length and half width in m.
    man_a, man_w : ndarray of shape (N, M)
        The manoeuvres' inputs per reaction step.
    dt : float
        Prediction step in s.
    eva, done : ndarray of shape (N, M, N + 1, 4) and (N, M)
        The ego's evasive poses, filled on demand (:func:`fill_evasion`), shared by all
        objects of a scene; ``done[j, m]`` marks the filled ones.

    Returns
    -------
    first : ndarray of shape (S,)
        Step of the first overlap with the known ego trajectory, -1 if none.
    react : ndarray of shape (S,)
        Latest step j < first from which some manoeuvre avoids the trajectory on steps
        j+1..N; -1 if none (unavoidable) or no collision.
    mask : ndarray of shape (S,)
        Bit m set when manoeuvre m avoids it from step ``react``; 0 when react = -1.
    """
    n_smp = traj.shape[0]
    n_pts = traj.shape[1]
    n_man = man_a.shape[1]
    er = math.hypot(ehl, ehw)
    orad = math.hypot(ohl, ohw)
    first = np.full(n_smp, -1, dtype=np.int64)
    react = np.full(n_smp, -1, dtype=np.int64)
    mask = np.zeros(n_smp, dtype=np.int64)
    for i in range(n_smp):
        c = -1
        for n in range(n_pts):
            if overlap(ego[n, 0], ego[n, 1], ego[n, 2], ego[n, 3], ehl, ehw, er,
                       traj[i, n, 0], traj[i, n, 1], traj[i, n, 2], traj[i, n, 3],
                       ohl, ohw, orad):
                c = n
                break
        first[i] = c
        if c <= 0:
            continue
        for j in range(c - 1, -1, -1):
            mk = 0
            for m in range(n_man):
                if _avoids(ego, v, man_a, man_w, dt, eva, done, j, m, traj, i, c, ehl, ehw, er,
                           ohl, ohw, orad):
                    mk |= 1 << m
            if mk != 0:
                react[i] = j
                mask[i] = mk
                break
    return first, react, mask


@njit(cache=True)
def expected_max(g: FloatArray, p: FloatArray) -> float:  # pragma: no cover - jit
    """E[max_k G_k] of independent discrete G_k with values g[k, :] and probabilities p[k, :].

    E[max] = ∫_0^u_max (1 - Π_k F_k(u)) du = u_max - ∫_0^u_max Π_k F_k(u) du for values in
    [0, ∞), with F_k the CDF of G_k. One ascending sweep over all values (sorted once,
    O(K·S log(K·S))) keeps the product Π_k F_k in a segment tree over the K objects
    (O(log K) per update, no division), so the whole is O(K·S·log(K·S)).
    Each row of p must sum to 1 (the last CDF step of each object is set to exactly 1).
    """
    n_obj = g.shape[0]
    n_smp = g.shape[1]
    flat = g.ravel()
    pflat = p.ravel()
    order = np.argsort(flat, kind="mergesort")
    size = 1
    while size < n_obj:
        size *= 2
    tree = np.ones(2 * size)
    for k in range(n_obj):
        tree[size + k] = 0.0
    for node in range(size - 1, 0, -1):
        tree[node] = tree[2 * node] * tree[2 * node + 1]
    cdf = np.zeros(n_obj)
    left = np.zeros(n_obj, dtype=np.int64)  # samples of object k not yet swept
    for k in range(n_obj):
        left[k] = n_smp
    integral = 0.0
    u_prev = 0.0
    idx = 0
    total = flat.shape[0]
    while idx < total:
        u = flat[order[idx]]
        integral += tree[1] * (u - u_prev)
        while idx < total and flat[order[idx]] == u:
            e = order[idx]
            k = e // n_smp
            left[k] -= 1
            cdf[k] = 1.0 if left[k] == 0 else cdf[k] + pflat[e]
            node = size + k
            tree[node] = cdf[k]
            node //= 2
            while node >= 1:
                tree[node] = tree[2 * node] * tree[2 * node + 1]
                node //= 2
            idx += 1
        u_prev = u
    return u_prev - integral


@njit(cache=True)
def ttr_weight_one(ttr: float, t_pnr: float, t_max: float, m: float) -> float:  # pragma: no cover
    """g(TTR) of eq. (5) for one TTR (see :func:`riskcore.risk.ttr_weight`)."""
    x = min(max(ttr, t_pnr), t_max)
    span = t_max - t_pnr
    if m == 0.0:
        g = (t_max - x) / span
    elif m * span <= 700.0:
        g = math.expm1(m * (t_max - x)) / math.expm1(m * span)
    else:
        g = (math.exp(-m * (x - t_pnr)) - math.exp(-m * span)) / (1.0 - math.exp(-m * span))
    return min(max(g, 0.0), 1.0)


@njit(cache=True)
def ttr_weight_many(ttr: FloatArray, t_pnr: float, t_max: float,
                    m: float) -> FloatArray:  # pragma: no cover - jit
    out = np.empty(ttr.shape[0])
    for i in range(ttr.shape[0]):
        out[i] = ttr_weight_one(ttr[i], t_pnr, t_max, m)
    return out


@njit(cache=True)
def weighted_mean(w: FloatArray, g: FloatArray) -> float:  # pragma: no cover - jit
    """Σ w g / Σ w, both sums in the same order (all g = 1 gives exactly 1)."""
    num = 0.0
    den = 0.0
    for i in range(w.shape[0]):
        num += w[i] * g[i]
        den += w[i]
    return num / den


@njit(cache=True)
def finish(first: NDArray[np.int64], react: NDArray[np.int64], dt: float, t_pnr: float,
           t_max: float, m: float, weight: FloatArray
           ) -> tuple[FloatArray, FloatArray, FloatArray, float]:  # pragma: no cover - jit
    """TTR (s), collision time (s), g(TTR) and r_k from the scan's step indices."""
    n = first.shape[0]
    ttr = np.empty(n)
    coll = np.empty(n)
    for i in range(n):
        if first[i] < 0:
            ttr[i] = np.inf
            coll[i] = np.inf
        else:
            coll[i] = first[i] * dt
            ttr[i] = react[i] * dt if react[i] >= 0 else 0.0
    g = ttr_weight_many(ttr, t_pnr, t_max, m)
    return ttr, coll, g, weighted_mean(weight, g)


@njit(cache=True)
def _bracket1(axis: FloatArray, x: float) -> tuple[int, float]:  # pragma: no cover - jit
    n = axis.shape[0]
    if n == 1:
        return 0, 0.0
    if x <= axis[0]:
        return 0, 0.0
    if x >= axis[n - 1]:
        return n - 2, 1.0
    i = np.searchsorted(axis, x, side="right") - 1
    if i > n - 2:
        i = n - 2
    return int(i), (x - axis[i]) / (axis[i + 1] - axis[i])


@njit(cache=True)
def bilinear(vaxis: FloatArray, xaxis: FloatArray, table: FloatArray, v: FloatArray,
             x: FloatArray) -> FloatArray:  # pragma: no cover - jit
    """Bilinear interpolation of table (len(vaxis), len(xaxis)) at the points (v, x),
    clamped at the edges; v and x flat arrays of equal length."""
    out = np.empty(v.shape[0])
    nv = vaxis.shape[0]
    nx = xaxis.shape[0]
    for k in range(v.shape[0]):
        i, wi = _bracket1(vaxis, v[k])
        j, wj = _bracket1(xaxis, x[k])
        i1 = min(i + 1, nv - 1)
        j1 = min(j + 1, nx - 1)
        lo = table[i, j] * (1.0 - wj) + table[i, j1] * wj
        hi = table[i1, j] * (1.0 - wj) + table[i1, j1] * wj
        out[k] = lo * (1.0 - wi) + hi * wi
    return out


@njit(cache=True)
def bilinear_pair(vaxis: FloatArray, xaxis: FloatArray, mean: FloatArray, std: FloatArray,
                  v: float, x: float) -> tuple[float, float]:  # pragma: no cover - jit
    """(mean, std) at one point (v, x): :func:`bilinear` of both tables, scalar."""
    i, wi = _bracket1(vaxis, v)
    j, wj = _bracket1(xaxis, x)
    i1 = min(i + 1, vaxis.shape[0] - 1)
    j1 = min(j + 1, xaxis.shape[0] - 1)
    lo = mean[i, j] * (1.0 - wj) + mean[i, j1] * wj
    hi = mean[i1, j] * (1.0 - wj) + mean[i1, j1] * wj
    m = lo * (1.0 - wi) + hi * wi
    lo = std[i, j] * (1.0 - wj) + std[i, j1] * wj
    hi = std[i1, j] * (1.0 - wj) + std[i1, j1] * wj
    return m, lo * (1.0 - wi) + hi * wi


@njit(cache=True)
def ttc_cv(ax: float, ay: float, apsi: float, al: float, aw: float, av: float, bx: float,
           by: float, bpsi: float, bl: float, bw: float, bv: float) -> float:  # pragma: no cover
    """TTC of two boxes at constant velocities (see riskcore.geometry)."""
    ca = math.cos(apsi)
    sa = math.sin(apsi)
    cb = math.cos(bpsi)
    sb = math.sin(bpsi)
    dx = bx - ax
    dy = by - ay
    rvx = bv * cb - av * ca
    rvy = bv * sb - av * sa
    ahl = 0.5 * al
    ahw = 0.5 * aw
    bhl = 0.5 * bl
    bhw = 0.5 * bw
    c11 = abs(ca * cb + sa * sb)
    c12 = abs(sa * cb - ca * sb)
    lo = 0.0
    hi = np.inf
    for k in range(4):
        if k == 0:
            ux, uy, r = ca, sa, ahl + bhl * c11 + bhw * c12
        elif k == 1:
            ux, uy, r = -sa, ca, ahw + bhl * c12 + bhw * c11
        elif k == 2:
            ux, uy, r = cb, sb, bhl + ahl * c11 + ahw * c12
        else:
            ux, uy, r = -sb, cb, bhw + ahl * c12 + ahw * c11
        d = dx * ux + dy * uy
        s = rvx * ux + rvy * uy
        if s == 0.0:
            if abs(d) >= r:
                return np.inf
            continue
        t1 = (-r - d) / s
        t2 = (r - d) / s
        lo = max(lo, min(t1, t2))
        hi = min(hi, max(t1, t2))
    return lo if lo < hi else np.inf


@njit(cache=True)
def thw_one(ex: float, ey: float, epsi: float, el: float, ew: float, ev: float, ox: float,
            oy: float, opsi: float, ol: float, ow: float) -> float:  # pragma: no cover - jit
    """Time headway of the ego to an object (see riskcore.geometry)."""
    ce = math.cos(epsi)
    se = math.sin(epsi)
    dx = ox - ex
    dy = oy - ey
    lon = dx * ce + dy * se
    lat = dy * ce - dx * se
    cd = abs(math.cos(opsi - epsi))
    sd = abs(math.sin(opsi - epsi))
    o_lon = 0.5 * ol * cd + 0.5 * ow * sd
    o_lat = 0.5 * ol * sd + 0.5 * ow * cd
    if not (abs(lat) < 0.5 * ew + o_lat and lon > 0.0 and ev > 0.0):
        return np.inf
    return max(lon - o_lon - 0.5 * el, 0.0) / ev


@njit(cache=True)
def ttc_thw_many(a: FloatArray, va: FloatArray, b: FloatArray, vb: FloatArray
                 ) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - jit
    """TTC and THW (a = ego) over rows ``[x, y, psi, length, width]`` of shape (n, 5)."""
    n = a.shape[0]
    ttc = np.empty(n)
    thw = np.empty(n)
    for i in range(n):
        ttc[i] = ttc_cv(a[i, 0], a[i, 1], a[i, 2], a[i, 3], a[i, 4], va[i],
                        b[i, 0], b[i, 1], b[i, 2], b[i, 3], b[i, 4], vb[i])
        thw[i] = thw_one(a[i, 0], a[i, 1], a[i, 2], a[i, 3], a[i, 4], va[i],
                         b[i, 0], b[i, 1], b[i, 2], b[i, 3], b[i, 4])
    return ttc, thw
