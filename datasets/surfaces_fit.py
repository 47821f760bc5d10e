"""Fit riskcore's input-distribution surfaces (seed 000, eq. 2-3) from trajectories.

Samples. Every trajectory (one vehicle: time t, speed v, optionally heading psi) is
resampled to ``rate`` Hz (linear interpolation). At every step k with one second of
trajectory ahead, one sample is taken::

    v0 = v(t_k)
    a0 = (v(t_k + h) - v(t_k - h)) / 2h                   current acceleration, h = 0.1 s
    a_bar = (v(t_k + 1 s) - v(t_k)) / 1 s                  mean acceleration, next second
    w0 = (psi(t_k + h) - psi(t_k - h)) / 2h                current turn rate
    w_bar = (psi(t_k + 1 s) - psi(t_k)) / 1 s              mean turn rate, next second

Fit. For each grid node (v0_i, x0_j) the maximum-likelihood Gaussian of a_bar (or w_bar)
given (v0, x0) is computed from kernel-weighted samples (the smoothing): weights
w = exp(-((v0 - v0_i) / dv)^2 / 2 - ((x0 - x0_j) / dx)^2 / 2) with (dv, dx) the grid
spacings. The mean is local-linear: weighted least squares of
y ~ c + b_x (x0 - x0_j) + b_v (v0 - v0_i), mean = c (a local constant, sum(w y) / sum(w),
would mix the slope of the mean into the spread); the std is the weighted ML estimate
sqrt(sum(w r^2) / sum(w)) of the residuals r of that fit. Where the 3x3 normal equations
are singular (no spread of the samples), the local constant is used. The kernel-weighted
count n_w = sum(w) (each weight <= 1: a sample on the node counts 1, one a grid step away
in one axis 0.61) is stored in ``count``. A node with n_w < ``min_count`` is sparse: it is
filled with the mean and std of the nearest node that is not (distance in grid steps), and
its count is 0. Samples of one trajectory are correlated, so n_w overstates the number of
independent observations.
The std has a floor (``std_floor``) so no cell is degenerate.

Mirror symmetry of the turn surface (the risk engine's left/right invariance needs it):
the turn samples are used together with their mirror images (w0, w_bar) -> (-w0, -w_bar),
the w0 axis is symmetric about 0, and the result is symmetrised exactly:
mean <- (mean - mean[:, ::-1]) / 2, std <- (std + std[:, ::-1]) / 2.

Trajectories: :func:`trajectories_from_egocentric` gives both vehicles' speeds and the
target's heading, psi = atan2(d(ego_y + target_dy)/dt, target_v) (the ego's heading is not
measured in the ego-centric format, so the ego contributes to the acceleration surface
only); :func:`trajectories_from_highd` gives every vehicle's speed and heading.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from datasets import egocentric as ec
from datasets.errors import DatasetError, FormatError
from riskcore import SURFACES_FORMAT as FORMAT
from riskcore import InputSurfaces

__all__ = [
    "SurfaceGrid",
    "fit_surface",
    "fit_surfaces",
    "input_samples",
    "trajectories_from_egocentric",
    "trajectories_from_highd",
    "write_surfaces",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SurfaceGrid:
    """Grid axes, smoothing and sparsity rules of the fit."""

    v0: tuple[float, float, float] = (0.0, 45.0, 2.5)  #: m/s: start, stop, step
    a0: tuple[float, float, float] = (-4.0, 4.0, 0.5)  #: m/s^2
    w0_max: float = 0.2  #: rad/s, the w0 axis is -w0_max..w0_max
    w0_step: float = 0.02  #: rad/s
    min_count: float = 30.0  #: effective samples below which a node is filled
    accel_std_floor: float = 0.05  #: m/s^2
    turn_std_floor: float = 0.002  #: rad/s
    rate: float = 10.0  #: Hz, resampling rate
    horizon: float = 1.0  #: s, "over the next second"

    def v_axis(self) -> FloatArray:
        lo, hi, step = self.v0
        return np.asarray(lo + step * np.arange(round((hi - lo) / step) + 1), dtype=np.float64)

    def a_axis(self) -> FloatArray:
        lo, hi, step = self.a0
        return np.asarray(lo + step * np.arange(round((hi - lo) / step) + 1), dtype=np.float64)

    def w_axis(self) -> FloatArray:
        n = round(self.w0_max / self.w0_step)
        return np.asarray(self.w0_step * np.arange(-n, n + 1), dtype=np.float64)


def trajectories_from_egocentric(frame: pd.DataFrame) -> pd.DataFrame:
    """Trajectories ``track_id, t, v, psi`` (psi NaN for the ego) from ego-centric events."""
    data = ec.validate_egocentric(frame)
    parts = []
    for event_id, ev in data.groupby(ec.EVENT_ID, sort=False):
        t = ev[ec.T].to_numpy()
        y = np.nan_to_num(ev[ec.EGO_Y].to_numpy(), nan=0.0) + ev[ec.TARGET_DY].to_numpy()
        vt = ev[ec.TARGET_V].to_numpy()
        lat = np.gradient(y, t) if len(t) > 1 else np.zeros_like(t)
        parts.append(pd.DataFrame({"track_id": f"{event_id}/target", "t": t, "v": vt,
                                   "psi": np.arctan2(lat, np.maximum(vt, 1e-6))}))
        parts.append(pd.DataFrame({"track_id": f"{event_id}/ego", "t": t,
                                   "v": ev[ec.EGO_V].to_numpy(), "psi": np.nan}))
    return pd.concat(parts, ignore_index=True)


def trajectories_from_highd(recording: Any) -> pd.DataFrame:
    """Trajectories ``track_id, t, v, psi`` of every vehicle of a highD recording."""
    from datasets.highd import road_frame

    road = road_frame(recording)
    return pd.DataFrame({
        "track_id": road["id"].astype(str).to_numpy(), "t": road["t"].to_numpy(),
        "v": np.hypot(road["vx"].to_numpy(), road["vy"].to_numpy()),
        "psi": np.arctan2(road["vy"].to_numpy(), road["vx"].to_numpy()),
    })


def input_samples(trajectories: pd.DataFrame, grid: SurfaceGrid | None = None
                  ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The (v0, x0, y) samples of the module docstring: (acceleration, turn) frames."""
    grid = grid or SurfaceGrid()
    for col in ("track_id", "t", "v", "psi"):
        if col not in trajectories.columns:
            raise FormatError(f"trajectories: missing column {col!r}")
    step = 1.0 / grid.rate
    ahead = round(grid.horizon * grid.rate)
    acc_parts, turn_parts = [], []
    for _, tr in trajectories.groupby("track_id", sort=False):
        t = tr["t"].to_numpy(dtype=np.float64)
        if len(t) < 2 or t[-1] - t[0] < grid.horizon + 2 * step:
            continue
        tg = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1)
        v = np.interp(tg, t, tr["v"].to_numpy(dtype=np.float64))
        k = np.arange(1, len(tg) - ahead)
        if k.size == 0:
            continue
        acc_parts.append(pd.DataFrame({
            "v0": v[k], "x0": (v[k + 1] - v[k - 1]) / (2 * step),
            "y": (v[k + ahead] - v[k]) / grid.horizon}))
        psi_raw = tr["psi"].to_numpy(dtype=np.float64)
        if np.isfinite(psi_raw).all():
            psi = np.interp(tg, t, np.unwrap(psi_raw))
            turn_parts.append(pd.DataFrame({
                "v0": v[k], "x0": (psi[k + 1] - psi[k - 1]) / (2 * step),
                "y": (psi[k + ahead] - psi[k]) / grid.horizon}))
    empty = pd.DataFrame({"v0": [], "x0": [], "y": []})
    acc = pd.concat(acc_parts, ignore_index=True) if acc_parts else empty
    turn = pd.concat(turn_parts, ignore_index=True) if turn_parts else empty
    return acc, turn


def fit_surface(
    v0: FloatArray, x0: FloatArray, y: FloatArray, v_axis: FloatArray, x_axis: FloatArray,
    *, min_count: float, std_floor: float,
) -> dict[str, FloatArray]:
    """Kernel-weighted ML Gaussian per node, sparse nodes filled (module docstring).

    Returns ``mean``, ``std``, ``count`` of shape (len(v_axis), len(x_axis)).
    """
    v0 = np.asarray(v0, dtype=np.float64)
    x0 = np.asarray(x0, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if v0.size == 0:
        raise DatasetError("surface fit: no samples")
    hv = float(np.median(np.diff(v_axis))) if len(v_axis) > 1 else 1.0
    hx = float(np.median(np.diff(x_axis))) if len(x_axis) > 1 else 1.0
    shape = (len(v_axis), len(x_axis))
    mean = np.zeros(shape)
    std = np.zeros(shape)
    count = np.zeros(shape)
    zx = (x0[None, :] - x_axis[:, None]) / hx  # (n_x, n_samples)
    kx = np.exp(-0.5 * zx**2)
    dx = x0[None, :] - x_axis[:, None]
    for i, vi in enumerate(v_axis):
        dv = v0 - vi
        kv = np.exp(-0.5 * (dv / hv) ** 2)
        w = kx * kv[None, :]  # (n_x, n)
        sw = w.sum(axis=1)
        count[i] = sw
        # local-linear weighted least squares y ~ c + b_x (x0 - x_j) + b_v (v0 - v_i)
        basis = np.stack([np.ones_like(dx), dx, np.broadcast_to(dv, dx.shape)], axis=-1)
        wb = w[..., None] * basis  # (n_x, n, 3)
        gram = np.einsum("jnk,jnl->jkl", wb, basis)
        rhs = wb.transpose(0, 2, 1) @ y  # (n_x, 3)
        yy = w @ (y * y)
        safe = np.where(sw > 0, sw, 1.0)
        const = (w @ y) / safe
        m = const.copy()
        var = yy / safe - const**2
        scale = np.maximum(np.abs(np.linalg.det(gram)), 0.0)
        ok = (sw > 0) & (scale > 1e-12 * np.maximum(sw, 1e-300) ** 3)
        if ok.any():
            theta = np.linalg.solve(gram[ok], rhs[ok][..., None])[..., 0]
            m[ok] = theta[:, 0]
            var[ok] = (yy[ok] - np.einsum("jk,jk->j", theta, rhs[ok])) / sw[ok]
        mean[i] = m
        std[i] = np.sqrt(np.maximum(var, 0.0))
    observed = count >= min_count
    if not observed.any():
        raise DatasetError(
            f"surface fit: no grid node has a kernel-weighted count of {min_count:g}; "
            "use more data or a lower min_count"
        )
    ii, jj = np.nonzero(observed)
    for i, j in zip(*np.nonzero(~observed), strict=True):
        d2 = (ii - i) ** 2 + (jj - j) ** 2
        best = int(np.argmin(d2))
        mean[i, j] = mean[ii[best], jj[best]]
        std[i, j] = std[ii[best], jj[best]]
    count[~observed] = 0.0
    return {"mean": mean, "std": np.maximum(std, std_floor), "count": count}


def fit_surfaces(
    trajectories: pd.DataFrame, *, grid: SurfaceGrid | None = None, source: str = "",
    notes: str = "",
) -> dict[str, Any]:
    """Fit both surfaces; returns the riskcore JSON form (``scengen.input-surfaces/1``).

    Parameters
    ----------
    trajectories : DataFrame
        Columns ``track_id``, ``t`` (s), ``v`` (m/s), ``psi`` (rad; NaN for a track whose
        heading is unknown: it then feeds the acceleration surface only).
    """
    grid = grid or SurfaceGrid()
    acc, turn = input_samples(trajectories, grid)
    if len(turn) == 0:
        raise DatasetError("surface fit: no trajectory has a heading, so no turn samples")
    v_axis, a_axis, w_axis = grid.v_axis(), grid.a_axis(), grid.w_axis()
    fa = fit_surface(acc["v0"].to_numpy(), acc["x0"].to_numpy(), acc["y"].to_numpy(),
                     v_axis, a_axis, min_count=grid.min_count, std_floor=grid.accel_std_floor)
    tv = np.concatenate([turn["v0"].to_numpy()] * 2)
    tx = np.concatenate([turn["x0"].to_numpy(), -turn["x0"].to_numpy()])
    ty = np.concatenate([turn["y"].to_numpy(), -turn["y"].to_numpy()])
    ft = fit_surface(tv, tx, ty, v_axis, w_axis, min_count=grid.min_count,
                     std_floor=grid.turn_std_floor)
    ft["mean"] = 0.5 * (ft["mean"] - ft["mean"][:, ::-1])
    ft["std"] = 0.5 * (ft["std"] + ft["std"][:, ::-1])
    ft["count"] = 0.5 * (ft["count"] + ft["count"][:, ::-1])
    method = (
        f"kernel-weighted ML Gaussians of the mean input over the next {grid.horizon:g} s "
        f"({len(acc)} acceleration samples, {len(turn)} turn samples x2 mirrored, "
        f"{grid.rate:g} Hz); local-linear fit with a Gaussian kernel of one grid step; "
        f"nodes with kernel-weighted counts below "
        f"{grid.min_count:g} filled from the nearest node (count 0); "
        f"std floors {grid.accel_std_floor:g} m/s^2 and {grid.turn_std_floor:g} rad/s; "
        "turn surface mirror-symmetric. Method: datasets.surfaces_fit, docs/datasets.md."
    )

    def surf(axis_x: FloatArray, f: dict[str, FloatArray]) -> dict[str, Any]:
        return {"v0": [float(x) for x in v_axis], "x0": [float(x) for x in axis_x],
                "mean": f["mean"].tolist(), "std": f["std"].tolist(),
                "count": np.round(f["count"], 3).tolist()}

    out = {"format": FORMAT, "interim": False, "source": source,
           "notes": (notes + " " + method).strip(),
           "accel": surf(a_axis, fa), "turn": surf(w_axis, ft)}
    InputSurfaces.from_dict(out, "fitted surfaces")  # same validation as riskcore's loader
    return out


def write_surfaces(surfaces: dict[str, Any], path: str | Path) -> Path:
    """Validate with riskcore's loader rules and write the JSON file."""
    InputSurfaces.from_dict(surfaces, str(path))
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(surfaces, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return p
