"""Least-squares fits of the cut-in motion models to measured motion.

Two independent fits (DESIGN.md, "The cut-in parameter vector"):

Lateral motion. With measured speed v(t), the model lateral position is::

    y(t) = y_s + int_{t0}^{t} v(s) sin(psi(s - t0)) ds
    psi(tau) = p_y1 p_t / pi (1 - cos(pi tau / p_t))   for 0 <= tau <= 2 p_t, else 0

and (p_y1, p_t, t0, y_s) minimise sum_k (y_k - y(t_k))^2 (scipy ``least_squares``, trust
region reflective, bounded). The integral is a cumulative trapezoid on the data's own time
grid (psi is C^1, so the error is O(dt^2): about 1e-3 m at 25 Hz). Starting values come
from the data: the displacement D, the peak lateral speed u (D = u p_t for this model),
and the time the midpoint is crossed (about t0 + p_t).

Longitudinal motion. The speed is a rectangular acceleration pulse, i.e. a ramp between
two plateaus::

    v(t) = v1 + (v2 - v1) clip((t - tau1) / (tau2 - tau1), 0, 1)

For fixed (tau1, tau2) this is linear in (v1, v2), so a grid over (tau1, tau2) with step
``grid_step`` (or span / 60 when coarser) is solved exactly (2x2 normal equations,
vectorised), and the best cell is refined with ``least_squares`` over all four. Then
p_a1 = (v2 - v1) / (tau2 - tau1), p_a2 = tau1 - t0, p_a3 = tau2 - tau1, p_v0 = v(t0).
A plateau step below ``min_step`` (m/s) counts as no pulse (p_a1 = p_a2 = p_a3 = 0,
p_v0 = mean speed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from datasets.errors import ExtractionError

__all__ = ["LateralFit", "PulseFit", "fit_lateral", "fit_pulse", "lateral_model"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LateralFit:
    """Result of :func:`fit_lateral`. Times in the clock of the data (s)."""

    p_y1: float  #: rad/s
    p_t: float  #: s
    t0: float  #: s, start of the lateral motion
    y_start: float  #: m, lateral position before the motion
    rms: float  #: m, RMS residual
    displacement: float  #: m, model y(t0 + 2 p_t) - y_start (signed)


@dataclass(frozen=True)
class PulseFit:
    """Result of :func:`fit_pulse`."""

    p_a1: float  #: m/s^2
    p_a2: float  #: s, relative to t0
    p_a3: float  #: s
    p_v0: float  #: m/s, model speed at t0
    rms: float  #: m/s, RMS residual


def _cumtrapz(f: FloatArray, t: FloatArray) -> FloatArray:
    out = np.empty_like(f)
    out[0] = 0.0
    np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t), out=out[1:])
    return out


def lateral_model(
    t: FloatArray, v: FloatArray, p_y1: float, p_t: float, t0: float, y_start: float
) -> FloatArray:
    """Model lateral position y(t_k) in m for measured speeds v_k; shapes (n,) -> (n,).

    When the motion starts before the data (t0 < t[0]), the part between t0 and t[0] is
    integrated with the first measured speed v[0] on a grid of the data's median step.
    """

    def psi(tau: FloatArray) -> FloatArray:
        inside = (tau >= 0.0) & (tau <= 2.0 * p_t)
        return np.where(inside, p_y1 * p_t / np.pi * (1.0 - np.cos(np.pi * tau / p_t)), 0.0)

    offset = 0.0
    if t0 < t[0]:
        step = float(np.median(np.diff(t)))
        m = max(int(np.ceil((t[0] - t0) / step)), 1) + 1
        pre = np.linspace(t0, t[0], m)
        offset = float(_cumtrapz(v[0] * np.sin(psi(pre - t0)), pre)[-1])
    return y_start + offset + _cumtrapz(v * np.sin(psi(t - t0)), t)


def _smoothed_rate(t: FloatArray, y: FloatArray, span: float) -> FloatArray:
    """Derivative dy/dt by central differences over about ``span`` seconds."""
    n = len(t)
    dt = float(np.median(np.diff(t)))
    m = max(round(span / 2.0 / dt), 1)
    lo = np.clip(np.arange(n) - m, 0, n - 1)
    hi = np.clip(np.arange(n) + m, 0, n - 1)
    return (y[hi] - y[lo]) / (t[hi] - t[lo])


def max_lateral_speed(t: FloatArray, y: FloatArray, span: float = 0.2) -> float:
    """Largest |dy/dt| in m/s, differences over ``span`` s (so rounding noise stays small)."""
    return float(np.max(np.abs(_smoothed_rate(t, y, span))))


def fit_lateral(
    t: FloatArray, y: FloatArray, v: FloatArray, max_early: float = 3.0
) -> LateralFit:
    """Fit (p_y1, p_t, t0, y_s) of the lateral model to measured positions.

    Parameters
    ----------
    t : ndarray of shape (n,)
        Time in s, strictly increasing; must cover the whole lateral motion.
    y : ndarray of shape (n,)
        Lateral position in m in a lane-fixed frame (+ = left).
    v : ndarray of shape (n,)
        Speed in m/s.
    max_early : float
        How many seconds before t[0] the motion may start (data cut mid-manoeuvre).

    Raises
    ------
    ExtractionError
        Too few points, no lateral motion, or the optimiser failed.
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if len(t) < 8:
        raise ExtractionError(f"lateral fit: needs at least 8 samples, got {len(t)}")
    t_ref = float(t[0])
    tt = t - t_ref
    n_edge = max(2, min(len(t) // 10, 5))
    y_a = float(np.median(y[:n_edge]))
    y_b = float(np.median(y[-n_edge:]))
    disp = y_b - y_a
    if abs(disp) < 0.5:
        raise ExtractionError(f"lateral fit: displacement {disp:.2f} m is too small")
    sign = 1.0 if disp > 0 else -1.0
    u = max(max_lateral_speed(tt, y, 0.4), 0.05)
    p_t0 = float(np.clip(abs(disp) / u, 0.4, 7.0))
    mid = y_a + 0.5 * disp
    k = int(np.argmax(sign * (y - mid) >= 0.0))
    t_mid = float(tt[k])
    v_mean = max(float(np.mean(v)), 1.0)
    p_y10 = sign * abs(disp) * np.pi / (2.0 * v_mean * p_t0**2)
    t_last = float(tt[-1])
    t00 = float(np.clip(t_mid - p_t0, -max_early, t_last - 0.5))

    def resid(x: FloatArray) -> FloatArray:
        return lateral_model(tt, v, x[0], x[1], x[2], x[3]) - y

    if sign > 0:
        lo = [1e-4, 0.2, -max_early, y_a - 5.0]
        hi = [1.5, 10.0, t_last - 0.2, y_a + 5.0]
    else:
        lo = [-1.5, 0.2, -max_early, y_a - 5.0]
        hi = [-1e-4, 10.0, t_last - 0.2, y_a + 5.0]
    x0 = np.clip([p_y10, p_t0, t00, y_a], np.add(lo, 1e-9), np.subtract(hi, 1e-9))
    try:
        res = least_squares(resid, x0, bounds=(lo, hi), x_scale=[0.01, 0.5, 0.5, 0.1],
                            xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=400)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ExtractionError(f"lateral fit failed: {exc}") from None
    p_y1, p_t, t0, ys = (float(a) for a in res.x)
    r = resid(res.x)
    model_end = lateral_model(tt, v, p_y1, p_t, t0, ys)
    t_end = t0 + 2.0 * p_t
    if t_end <= tt[-1]:
        disp_model = float(np.interp(t_end, tt, model_end)) - ys
    else:
        disp_model = float(model_end[-1]) - ys
    return LateralFit(
        p_y1=p_y1, p_t=p_t, t0=t0 + t_ref, y_start=ys,
        rms=float(np.sqrt(np.mean(r**2))), displacement=disp_model,
    )


def _ramp_grid(t: FloatArray, v: FloatArray, step: float, min_dur: float
               ) -> tuple[float, float, float, float]:
    """Best (tau1, tau2, v1, v2) on a grid of tau with spacing ``step``."""
    cand = np.arange(t[0], t[-1] + 1e-9, step)
    i, j = np.triu_indices(len(cand), k=1)
    keep = cand[j] - cand[i] >= min_dur - 1e-12
    tau1 = cand[i][keep][:, None]
    tau2 = cand[j][keep][:, None]
    r = np.clip((t[None, :] - tau1) / (tau2 - tau1), 0.0, 1.0)
    q = 1.0 - r
    s00 = np.sum(q * q, axis=1)
    s01 = np.sum(q * r, axis=1)
    s11 = np.sum(r * r, axis=1)
    b0 = q @ v
    b1 = r @ v
    det = s00 * s11 - s01 * s01
    ok = det > 1e-9 * (s00 * s11 + 1e-300)
    det_safe = np.where(ok, det, 1.0)
    v1 = (s11 * b0 - s01 * b1) / det_safe
    v2 = (s00 * b1 - s01 * b0) / det_safe
    rss = float(v @ v) - (v1 * b0 + v2 * b1)
    rss = np.where(ok, rss, np.inf)
    best = int(np.argmin(rss))
    return float(tau1[best, 0]), float(tau2[best, 0]), float(v1[best]), float(v2[best])


def fit_pulse(
    t: FloatArray, v: FloatArray, t0: float, *, grid_step: float = 0.2,
    min_duration: float = 0.2, min_step: float = 0.05,
) -> PulseFit:
    """Fit the rectangular acceleration pulse to measured speeds.

    Parameters
    ----------
    t : ndarray of shape (n,)
        Time in s, strictly increasing (the fit window).
    v : ndarray of shape (n,)
        Speed in m/s.
    t0 : float
        Start of the lateral motion (s, same clock): p_a2 is relative to it.
    grid_step : float
        Spacing in s of the (tau1, tau2) grid before refinement (coarsened to span / 60
        for long windows).
    min_duration : float
        Shortest pulse in s.
    min_step : float
        Plateau difference in m/s below which the fit reports no pulse.
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if len(t) < 6:
        raise ExtractionError(f"speed fit: needs at least 6 samples, got {len(t)}")
    t_ref = float(t[0])
    tt = t - t_ref
    span = float(tt[-1])
    if span < 2.0 * min_duration:
        raise ExtractionError(f"speed fit: window of {span:.2f} s is too short")
    # at most ~60 grid candidates: long windows get a coarser grid, refined below
    step = max(grid_step, span / 60.0)
    tau1, tau2, v1, v2 = _ramp_grid(tt, v, step, min(min_duration, step))

    def model(x: FloatArray) -> FloatArray:
        a, d, w1, w2 = x
        return w1 + (w2 - w1) * np.clip((tt - a) / d, 0.0, 1.0)

    lo = [0.0, min_duration, -np.inf, -np.inf]
    hi = [span - min_duration, span, np.inf, np.inf]
    x0 = np.array([tau1, tau2 - tau1, v1, v2])
    x0[:2] = np.clip(x0[:2], np.add(lo[:2], 1e-9), np.subtract(hi[:2], 1e-9))
    res = least_squares(lambda x: model(x) - v, x0, bounds=(lo, hi),
                        x_scale=[0.1, 0.1, 0.1, 0.1], max_nfev=200)
    x = res.x if res.cost <= 0.5 * float(np.sum((model(x0) - v) ** 2)) else x0
    a, d, w1, w2 = (float(z) for z in x)
    if abs(w2 - w1) < min_step:
        mean = float(np.mean(v))
        return PulseFit(0.0, 0.0, 0.0, mean, float(np.sqrt(np.mean((v - mean) ** 2))))
    p_a1 = (w2 - w1) / d
    p_a2 = a + t_ref - t0
    vt0 = w1 + (w2 - w1) * float(np.clip((t0 - t_ref - a) / d, 0.0, 1.0))
    rms = float(np.sqrt(np.mean((model(x) - v) ** 2)))
    return PulseFit(p_a1=p_a1, p_a2=p_a2, p_a3=d, p_v0=vt0, rms=rms)
