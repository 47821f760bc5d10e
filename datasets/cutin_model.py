"""The cut-in parameter vector of DESIGN.md and the kinematics it describes.

One place for the names and the motion model, used by extraction (``datasets``: fit the
model to measured motion) and by the scenario builder (``sampler``: turn a sampled vector
into trajectories). Time t = 0 is the start of the cutter's lateral motion.

Lateral model (JARI slides, made concrete in DESIGN.md)::

    yaw_rate(t) = p_y1 sin(pi t / p_t)                 for 0 <= t <= 2 p_t, else 0
    psi(t)      = p_y1 p_t / pi (1 - cos(pi t / p_t))  for 0 <= t <= 2 p_t, else 0

so the heading peaks at t = p_t with 2 p_y1 p_t / pi and is back to 0 at t = 2 p_t.

Longitudinal model::

    a(t) = p_a1  for p_a2 <= t < p_a2 + p_a3, else 0
    v(t) = p_v0 + p_a1 (c(t) - c(0)),  c(t) = clip(t - p_a2, 0, p_a3)

so v(0) = p_v0 whatever the sign of p_a2 (a pulse may start before the lateral motion).

Position relative to the cutter's position at t = 0::

    x(t) = int_0^t v(s) cos psi(s) ds,   y(t) = int_0^t v(s) sin psi(s) ds

integrated numerically during the lane change, 0 <= t <= 2 p_t, by composite 4-point
Gauss-Legendre quadrature on panels of at most ``PANEL`` (0.1 s; shorter for a short or
sharp lane change, ``panel_width``) whose edges include the pulse edges, where the speed
has a kink: between them the integrand is smooth (analytic), so the rule's error is
O(h^8 f^(8)), about 1e-12 m here. A time between two panel edges gets the integral from
the edge before it by the same rule (no interpolation). Outside the lane change the
heading is 0, y is constant and x is the exact integral of the piecewise linear speed.
``trajectory(p)`` integrates once for many evaluations (the scenario builder).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datasets.errors import DatasetError

FloatArray = NDArray[np.float64]

#: The parameter vector, in DESIGN.md's order, with units.
PARAM_NAMES: tuple[str, ...] = ("p_y1", "p_t", "p_a1", "p_a2", "p_a3", "p_v0", "dv", "gap")
PARAM_UNITS: dict[str, str] = {
    "p_y1": "rad/s",
    "p_t": "s",
    "p_a1": "m/s^2",
    "p_a2": "s",
    "p_a3": "s",
    "p_v0": "m/s",
    "dv": "m/s",
    "gap": "m",
}
PARAM_DOCS: dict[str, str] = {
    "p_y1": "yaw-rate amplitude; + = towards the left",
    "p_t": "half the lane-change duration",
    "p_a1": "cutter's longitudinal acceleration during the pulse",
    "p_a2": "pulse start (relative to the start of the lateral motion)",
    "p_a3": "pulse duration (>= 0)",
    "p_v0": "cutter's speed at t = 0",
    "dv": "v_ego - v_cutter at the crossing moment (> 0: closing)",
    "gap": "bumper-to-bumper longitudinal gap at the crossing moment",
}

#: the longest panel of the lateral quadrature, s (``panel_width``)
PANEL = 0.1
#: 4-point Gauss-Legendre nodes on [-1, 1] and their weights
GL_NODES = (-0.8611363115940526, -0.33998104358485626, 0.33998104358485626,
            0.8611363115940526)
GL_WEIGHTS = (0.34785484513745385, 0.6521451548625461, 0.6521451548625461,
              0.34785484513745385)

#: Default lane width in m (German motorway lanes are 3.5-3.75 m; highD's median is ~3.75).
DEFAULT_LANE_WIDTH = 3.75


class CutInParamError(DatasetError):
    """A parameter vector is incomplete or outside what the kinematic model can represent."""


@dataclass(frozen=True)
class CutInParams:
    """A cut-in parameter vector (DESIGN.md). SI units."""

    p_y1: float
    p_t: float
    p_a1: float
    p_a2: float
    p_a3: float
    p_v0: float
    dv: float
    gap: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, float]) -> CutInParams:
        missing = [name for name in PARAM_NAMES if name not in values]
        if missing:
            raise CutInParamError(f"missing parameter(s): {', '.join(missing)}")
        out = cls(**{name: float(values[name]) for name in PARAM_NAMES})
        out.validate()
        return out

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in PARAM_NAMES}

    def validate(self) -> None:
        for name in PARAM_NAMES:
            if not np.isfinite(getattr(self, name)):
                raise CutInParamError(f"{name}: must be finite, got {getattr(self, name)!r}")
        if self.p_t <= 0:
            raise CutInParamError(f"p_t: must be > 0 s, got {self.p_t}")
        if self.p_a3 < 0:
            raise CutInParamError(f"p_a3: pulse duration must be >= 0 s, got {self.p_a3}")

    @property
    def ttc(self) -> float:
        """TTC = gap / dv at the crossing moment when dv > 0, else +inf (s)."""
        return float(ttc_from_gap_dv(self.gap, self.dv))


def ttc_from_gap_dv(gap: ArrayLike, dv: ArrayLike) -> FloatArray:
    """Vectorised TTC = gap / dv for dv > 0, +inf otherwise (s). Shapes broadcast."""
    gap_a = np.asarray(gap, dtype=np.float64)
    dv_a = np.asarray(dv, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(dv_a > 0, gap_a / np.where(dv_a > 0, dv_a, 1.0), np.inf)
    return np.asarray(out, dtype=np.float64)


def yaw_rate(p: CutInParams, t: ArrayLike) -> FloatArray:
    """psi_dot(t) in rad/s."""
    t_a = np.asarray(t, dtype=np.float64)
    inside = (t_a >= 0.0) & (t_a <= 2.0 * p.p_t)
    return np.where(inside, p.p_y1 * np.sin(np.pi * t_a / p.p_t), 0.0)


def heading(p: CutInParams, t: ArrayLike) -> FloatArray:
    """psi(t) in rad (closed form of the integral of ``yaw_rate`` from 0)."""
    t_a = np.asarray(t, dtype=np.float64)
    inside = (t_a >= 0.0) & (t_a <= 2.0 * p.p_t)
    return np.where(inside, p.p_y1 * p.p_t / np.pi * (1.0 - np.cos(np.pi * t_a / p.p_t)), 0.0)


def acceleration(p: CutInParams, t: ArrayLike) -> FloatArray:
    """a(t) in m/s^2: the rectangular pulse."""
    t_a = np.asarray(t, dtype=np.float64)
    return np.where((t_a >= p.p_a2) & (t_a < p.p_a2 + p.p_a3), p.p_a1, 0.0)


def speed(p: CutInParams, t: ArrayLike) -> FloatArray:
    """v(t) in m/s, with v(0) = p_v0."""
    t_a = np.asarray(t, dtype=np.float64)
    c = np.clip(t_a - p.p_a2, 0.0, p.p_a3)
    c0 = np.clip(-p.p_a2, 0.0, p.p_a3)
    return p.p_v0 + p.p_a1 * (c - c0)


@dataclass(frozen=True)
class CutInMotion:
    """The cutter's motion relative to its own position at t = 0. Arrays of shape (n,)."""

    t: FloatArray
    x: FloatArray
    y: FloatArray
    psi: FloatArray
    v: FloatArray
    a: FloatArray
    yaw_rate: FloatArray


def _with_points(base: FloatArray, points: list[float]) -> FloatArray:
    """``np.unique(np.concatenate([base, points]))`` for an increasing ``base`` and a few
    points, without sorting the whole grid."""
    if base.size < 2 or not bool((base[1:] > base[:-1]).all()):
        return np.unique(np.concatenate([base, points]))
    extra = np.unique(np.asarray(points, dtype=np.float64))
    at = np.searchsorted(base, extra)
    new = np.array([e for e, k in zip(extra.tolist(), at.tolist(), strict=True)
                    if not (k < base.size and base[k] == e)], dtype=np.float64)
    return np.insert(base, np.searchsorted(base, new), new) if new.size else base


def _pulse_integral(p: CutInParams, t: FloatArray) -> FloatArray:
    """``int_0^t v(s) ds`` in m, exact: v is piecewise linear (``speed``)."""
    a2, a3 = p.p_a2, p.p_a3

    def h(s: FloatArray | float) -> FloatArray:  # antiderivative of clip(s - a2, 0, a3)
        u = np.clip(np.asarray(s, dtype=np.float64) - a2, 0.0, a3)
        return np.asarray(0.5 * u * u + a3 * np.maximum(np.asarray(s) - a2 - a3, 0.0),
                          dtype=np.float64)

    c0 = min(max(-a2, 0.0), a3)
    return np.asarray(p.p_v0 * t + p.p_a1 * (h(t) - h(0.0) - c0 * t), dtype=np.float64)


def panel_width(p_t: float, p_y1: float, longest: float = PANEL) -> float:
    """The longest quadrature panel of a lane change, s: ``longest``, at most p_t / 8 (a
    sixteenth of the lane change) and 0.25 rad of yaw rate times it."""
    w = min(longest, p_t / 8.0)
    if p_y1 != 0.0:
        w = min(w, 0.25 / abs(p_y1))
    return w


def _gl(p: CutInParams, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``int_a^b v cos psi`` and ``int_a^b v sin psi`` by 4-point Gauss-Legendre (one panel
    each; no pulse edge inside), the same arithmetic as the batch builder's kernel."""
    mid = 0.5 * (a + b)
    half = 0.5 * (b - a)
    amp = p.p_y1 * p.p_t / np.pi
    sx = np.zeros_like(mid)
    sy = np.zeros_like(mid)
    for node, w in zip(GL_NODES, GL_WEIGHTS, strict=True):
        s = mid + half * node
        v = speed(p, s)
        psi = amp * (1.0 - np.cos(np.pi * s / p.p_t))
        sx = sx + w * (v * np.cos(psi))
        sy = sy + w * (v * np.sin(psi))
    return half * sx, half * sy


class CutInTrajectory:
    """The cutter's path of one vector, integrated once (``trajectory``).

    Inside the lane change (0 <= t <= 2 p_t) x and y are integrated panel by panel
    (module docstring; panels of at most ``panel_width(p_t, p_y1, substep)``, the pulse
    edges among their edges) and, at a time between two edges, from the edge before it;
    outside it the heading is 0, so y is constant and x is the exact integral of the
    piecewise linear speed.
    """

    def __init__(self, p: CutInParams, substep: float = PANEL) -> None:
        self.p = p
        end = 2.0 * p.p_t
        n_sub = max(int(np.ceil(end / panel_width(p.p_t, p.p_y1, substep))), 1)
        step = end / n_sub
        base = np.arange(n_sub + 1, dtype=np.float64) * step
        base[n_sub] = end
        edges = [p.p_a2, p.p_a2 + p.p_a3]
        grid = _with_points(base, [e for e in edges if 0.0 < e < end])
        dx, dy = _gl(p, grid[:-1], grid[1:])
        self.grid = grid
        self.x = np.concatenate([[0.0], np.cumsum(dx)])
        self.y = np.concatenate([[0.0], np.cumsum(dy)])
        self.end = end
        self._s_end = float(_pulse_integral(p, np.array([end]))[0])

    def _inside(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """x, y at times 0 <= t <= end: the edge before t plus the panel's rule to t."""
        j = np.searchsorted(self.grid, t, side="right") - 1
        j = np.clip(j, 0, self.grid.size - 1)
        dx, dy = _gl(self.p, self.grid[j], t)
        return self.x[j] + dx, self.y[j] + dy

    def xy(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """x(t), y(t) in m relative to the position at t = 0."""
        t_a = np.atleast_1d(np.asarray(t, dtype=np.float64))
        x = np.empty_like(t_a)
        y = np.empty_like(t_a)
        before = t_a < 0.0
        after = t_a > self.end
        inside = ~(before | after)
        if inside.any():
            x[inside], y[inside] = self._inside(t_a[inside])
        if before.any():
            x[before] = _pulse_integral(self.p, t_a[before])
            y[before] = 0.0
        if after.any():
            x[after] = self.x[-1] + (_pulse_integral(self.p, t_a[after]) - self._s_end)
            y[after] = self.y[-1]
        return x, y

    def motion(self, t: ArrayLike) -> CutInMotion:
        """The kinematics at times ``t`` (s, any order, may be negative)."""
        p = self.p
        t_a = np.atleast_1d(np.asarray(t, dtype=np.float64))
        x, y = self.xy(t_a)
        return CutInMotion(t=t_a, x=x, y=y, psi=heading(p, t_a), v=speed(p, t_a),
                           a=acceleration(p, t_a), yaw_rate=yaw_rate(p, t_a))

    def crossing_time(self, offset: float) -> float:
        """First t in [0, 2 p_t] at which |y(t)| reaches ``offset`` (m), to rounding
        (``crossing_root``); raises CutInParamError when it never does."""
        if offset <= 0:
            raise CutInParamError(f"offset: must be > 0 m, got {offset}")
        y = np.abs(self.y)
        above = np.flatnonzero(y >= offset)
        if above.size == 0:
            raise CutInParamError(
                f"lateral displacement {y.max():.3f} m never reaches {offset:.3f} m: "
                "p_y1 * p_t too small for a lane change"
            )
        i = int(above[0])
        if i == 0:
            return 0.0
        return crossing_root(self.p, float(self.grid[i - 1]), float(self.grid[i]),
                             float(self.y[i - 1]), float(self.y[i]), offset)


def crossing_root(p: CutInParams, a: float, b: float, y_a: float, y_b: float,
                  offset: float) -> float:
    """The t in [a, b] (one panel) with |y(t)| = offset, given |y(a)| < offset <= |y(b)|:
    Newton's method on the panel's rule (|y| is monotone: the heading keeps the sign of
    p_y1 and the speed is >= 0), kept inside the bracket by bisection."""
    lo, hi = a, b
    ya, yb = abs(y_a), abs(y_b)
    tau = a + (b - a) * (offset - ya) / (yb - ya)
    one = np.empty(1)
    amp = p.p_y1 * p.p_t / np.pi
    for _ in range(60):
        one[0] = tau
        _, dy = _gl(p, np.array([a]), one)
        g = abs(y_a + float(dy[0])) - offset
        if g == 0.0:
            break
        if g < 0.0:
            lo = tau
        else:
            hi = tau
        d = abs(float(speed(p, tau)) * np.sin(amp * (1.0 - np.cos(np.pi * tau / p.p_t))))
        nt = tau - g / d if d > 0.0 else np.nan
        if not lo < nt < hi:
            nt = 0.5 * (lo + hi)
        if abs(nt - tau) <= 1e-15 * max(1.0, abs(tau)) or hi - lo <= 1e-15 * max(1.0, hi):
            tau = nt
            break
        tau = nt
    return float(tau)


def trajectory(p: CutInParams, substep: float = PANEL) -> CutInTrajectory:
    """The cutter's path of ``p`` (:class:`CutInTrajectory`), for many evaluations."""
    return CutInTrajectory(p, substep)


def motion(p: CutInParams, t: ArrayLike, substep: float = PANEL) -> CutInMotion:
    """Evaluate the cut-in kinematics at times ``t`` (s, any order, may be negative).

    Parameters
    ----------
    p : CutInParams
    t : array-like of shape (n,)
    substep : float
        The longest quadrature panel in s for x(t), y(t) during the lane change
        (``panel_width``; outside it they are exact).
    """
    t_a = np.atleast_1d(np.asarray(t, dtype=np.float64))
    if t_a.size == 0:
        empty = np.zeros(0)
        return CutInMotion(empty, empty, empty, empty, empty, empty, empty)
    return CutInTrajectory(p, substep).motion(t_a)


def lateral_displacement(p: CutInParams, substep: float = PANEL) -> float:
    """Total lateral displacement y(2 p_t) in m (signed, + = to the left)."""
    return float(motion(p, [2.0 * p.p_t], substep=substep).y[0])


def crossing_time(p: CutInParams, offset: float, substep: float = PANEL) -> float:
    """First t in [0, 2 p_t] at which |y(t)| reaches ``offset`` (m), e.g. half a lane width.

    The cutter starts at a lane centre, so with the ego at the centre of the neighbouring
    lane the lane marking lies at ``offset = lane_width / 2``. Raises CutInParamError when
    the lateral motion never gets that far (the vector is not a cut-in).
    """
    if offset <= 0:
        raise CutInParamError(f"offset: must be > 0 m, got {offset}")
    return CutInTrajectory(p, substep).crossing_time(offset)
