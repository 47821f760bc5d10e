"""A straightforward reference implementation of the scene risk (seed 000, II-III).

Written independently of riskcore's kernels, for clarity over speed: the textbook CTRA
solution (with an ω = 0 branch), box overlap by projecting the four corners of both boxes
on the four edge normals, and the TTR as a plain forward scan over *every* reaction step
and manoeuvre and *every* later time step (no early exit, no broad phase, no ordering
tricks). Weights with scipy's normal pdf, g with the paper's formula as printed, r_dep by
enumerating all outcomes.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm


def ref_ctra(x0: float, y0: float, psi0: float, v0: float, a: float, w: float,
             tau: float) -> tuple[float, float, float]:
    """Textbook CTRA closed form; no reversing (stop at v = 0, then frozen)."""
    if a < 0 and -a * tau > v0:  # stops before tau (v0 / -a could overflow otherwise)
        tau = v0 / -a
    elif a == 0 and v0 <= 0:
        tau = 0.0
    psi = psi0 + w * tau
    v = v0 + a * tau
    if abs(w * tau) < 1e-4:
        # tiny turn: expand to second order in ω (relative error ~ (ωτ)^4 < 1e-16)
        lon = v0 * tau + a * tau**2 / 2 - w * w * (v0 * tau**3 / 6 + a * tau**4 / 8)
        lat = w * (v0 * tau**2 / 2 + a * tau**3 / 3)
        return (x0 + lon * math.cos(psi0) - lat * math.sin(psi0),
                y0 + lon * math.sin(psi0) + lat * math.cos(psi0), psi)
    x = x0 + (v * math.sin(psi) - v0 * math.sin(psi0)) / w \
        + a * (math.cos(psi) - math.cos(psi0)) / (w * w)
    y = y0 + (-v * math.cos(psi) + v0 * math.cos(psi0)) / w \
        + a * (math.sin(psi) - math.sin(psi0)) / (w * w)
    return x, y, psi


def corners(x: np.ndarray, y: np.ndarray, psi: np.ndarray, length: float,
            width: float) -> np.ndarray:
    """Corners of boxes, shape (n, 4, 2)."""
    c, s = np.cos(psi), np.sin(psi)
    out = np.empty((x.shape[0], 4, 2))
    for k, (sl, sw) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        out[:, k, 0] = x + sl * length / 2 * c - sw * width / 2 * s
        out[:, k, 1] = y + sl * length / 2 * s + sw * width / 2 * c
    return out


def ref_overlap(pa: np.ndarray, la: float, wa: float, pb: np.ndarray, lb: float,
                wb: float) -> np.ndarray:
    """Positive-area overlap of box pairs; pa, pb of shape (n, 3) = [x, y, psi]."""
    ca = corners(pa[:, 0], pa[:, 1], pa[:, 2], la, wa)
    cb = corners(pb[:, 0], pb[:, 1], pb[:, 2], lb, wb)
    separated = np.zeros(pa.shape[0], dtype=bool)
    for psi in (pa[:, 2], pb[:, 2]):
        c, s = np.cos(psi), np.sin(psi)
        for ux, uy in ((c, s), (-s, c)):  # the edge normals (not cos(ψ + π/2): rounding)
            u = np.stack([ux, uy], axis=-1)[:, None, :]
            qa = (ca * u).sum(-1)
            qb = (cb * u).sum(-1)
            separated |= (qa.max(1) <= qb.min(1)) | (qb.max(1) <= qa.min(1))
    return ~separated


@dataclass
class RefObject:
    x: float
    y: float
    psi: float
    v: float
    length: float
    width: float
    mean_a: float
    std_a: float
    mean_w: float
    std_w: float


@dataclass
class RefSettings:
    horizon: float = 3.0
    dt: float = 0.1
    n_a: int = 10
    n_omega: int = 10
    t_pnr: float = 0.5
    t_max: float = 2.0
    m: float = 1.0
    brake_max: float = 8.0
    accel_max: float = 2.0
    lat_accel_max: float = 6.0
    min_turn_radius: float = 5.5


def ref_g(ttr: float, s: RefSettings) -> float:
    """Eq. (5) as printed."""
    if math.isinf(ttr):
        return 0.0
    if s.m > 0:
        e = math.exp(-s.m * (s.t_max - s.t_pnr))
        gbar = (math.exp(-s.m * (ttr - s.t_pnr)) - e) / (1 - e)
    else:
        gbar = (s.t_max - ttr) / (s.t_max - s.t_pnr)
    return min(1.0, max(0.0, gbar))


def ref_manoeuvres(v: float, s: RefSettings) -> list[tuple[float, float]]:
    """(a, ω) of steer left, steer right, brake, accelerate at speed v."""
    if v <= 0:
        w = 0.0
    elif v * v >= s.lat_accel_max * s.min_turn_radius:  # then lat / v is the smaller one
        w = s.lat_accel_max / v
    else:  # (and lat / v might overflow for a tiny v)
        w = v / s.min_turn_radius
    return [(0.0, w), (0.0, -w), (-s.brake_max, 0.0), (s.accel_max, 0.0)]


def ref_object(ego: np.ndarray, ego_size: tuple[float, float], obj: RefObject,
               s: RefSettings) -> dict[str, np.ndarray | float]:
    """TTR, evasion mask, collision step, weights and r_k of one object.

    ego : shape (N + 1, 4) = [x, y, psi, v] on the prediction grid.
    """
    n = round(s.horizon / s.dt)
    za = np.linspace(-3, 3, s.n_a) if s.n_a > 1 else np.zeros(1)
    zw = np.linspace(-3, 3, s.n_omega) if s.n_omega > 1 else np.zeros(1)
    a_vals = obj.mean_a + obj.std_a * za
    w_vals = obj.mean_w + obj.std_w * zw
    inputs = [(a, w) for a in a_vals for w in w_vals]
    dens = np.array([norm.pdf(a, obj.mean_a, obj.std_a) * norm.pdf(w, obj.mean_w, obj.std_w)
                     for a, w in inputs])
    p = dens / dens.sum()
    el, ew = ego_size
    ttr = np.full(len(inputs), np.inf)
    mask = np.zeros(len(inputs), dtype=np.int64)
    first = np.full(len(inputs), -1)
    for i, (a, w) in enumerate(inputs):
        traj = np.array([ref_ctra(obj.x, obj.y, obj.psi, obj.v, a, w, k * s.dt)
                         for k in range(n + 1)])
        hit = ref_overlap(ego[:, :3], el, ew, traj, obj.length, obj.width)
        if not hit.any():
            continue
        c = int(np.flatnonzero(hit)[0])
        first[i] = c
        ttr[i] = 0.0
        for j in range(c):  # every reaction step before the first collision
            mk = 0
            for bit, (ea, eww) in enumerate(ref_manoeuvres(ego[j, 3], s)):
                steps = range(j + 1, n + 1)
                eva = np.array([ref_ctra(ego[j, 0], ego[j, 1], ego[j, 2], ego[j, 3], ea, eww,
                                         (k - j) * s.dt) for k in steps])
                if not ref_overlap(eva, el, ew, traj[j + 1:], obj.length, obj.width).any():
                    mk |= 1 << bit
            if mk:
                ttr[i] = j * s.dt
                mask[i] = mk
    g = np.array([ref_g(t, s) for t in ttr])
    return {"ttr": ttr, "mask": mask, "first": first, "p": p, "g": g,
            "risk": float((p * g).sum())}


def ref_r_dep(g: list[np.ndarray], p: list[np.ndarray]) -> float:
    """Eq. (8) by enumerating all N_smp^N_TO outcomes (min TTR ↔ max g)."""
    total = 0.0
    for combo in itertools.product(*(range(len(gk)) for gk in g)):
        ps = math.prod(p[k][i] for k, i in enumerate(combo))
        total += ps * max(g[k][i] for k, i in enumerate(combo))
    return total
