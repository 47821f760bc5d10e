"""Parameter vector -> concrete scenario (the geometry of one sampled cut-in).

Scenario time ``t`` runs from 0 to ``duration`` in steps of ``dt`` (0.1 s). The cutter's
lateral motion starts at ``t = lead_in`` (default 2.5 s), so the kinematic model's own time
is ``tau = t - lead_in``.

Duration (adaptive by default): a scenario lasts until its conflict is resolved for the
scripted ego (:func:`riskcore.criticality.conflict_resolution`: contact; the cutter done
with its lane change and acceleration pulse and the gap no longer shrinking; or the
cutter left behind), plus the risk horizon (``horizon``, 3 s, riskcore's Table II
default), rounded up to whole steps, and at least until the cutter's lane change and
acceleration pulse are over (a reacting reference driver meets the cutter later than the
scripted ego: its figures must not come from a cut-off either). A requested
``duration`` may be longer, never shorter than the resolution: no criticality figure may
come from a cut-off. The provenance records ``t_resolved`` and ``resolution``. A
manoeuvre lasting longer than a scenario may (3600 s) is refused.

Geometry (road frame: x along the road, y to the left, positions are vehicle centres):

* Ego: centre of its lane, ``y = 0``, heading 0, constant speed
  ``v_ego = v_cutter(tau_c) + dv``, ``x_ego(t) = v_ego t`` (it starts at x = 0).
* Cutter: starts at the centre of the adjacent lane on the side given by the sign of
  ``p_y1`` (``p_y1 > 0`` moves left, so it starts on the right, ``y = -lane_width``;
  ``p_y1 < 0`` starts at ``y = +lane_width``) and moves by
  ``datasets.cutin_model.motion``: yaw rate ``p_y1 sin(pi tau / p_t)``, the acceleration
  pulse ``(p_a1, p_a2, p_a3)``, speed ``p_v0`` at ``tau = 0``. Before ``tau = 0`` it drives
  straight (at constant speed unless the pulse starts earlier).
* Crossing moment ``tau_c = trajectory(p).crossing_time(lane_width / 2)``: the cutter's centre is on
  the lane marking. The cutter's initial x is chosen so that at ``tau_c`` the
  bumper-to-bumper gap ``x_cut - x_ego - (length_cut + length_ego) / 2`` equals ``gap``;
  ``dv = v_ego - v_cut(tau_c)`` holds by the choice of ``v_ego``. Both hold exactly on the
  continuous trajectory; ``tau_c`` generally falls between grid steps and is stored in the
  provenance (``t_cross``, scenario time).

Default vehicle sizes: 4.5 m x 1.8 m (a mid-size passenger car) for both vehicles.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from datasets import (
    DEFAULT_LANE_WIDTH,
    PARAM_NAMES,
    CutInParamError,
    CutInParams,
    CutInTrajectory,
    speed,
    trajectory,
)
from riskcore import ConcreteScenario, Track
from riskcore.criticality import conflict_resolution
from sampler.errors import BuilderError

__all__ = [
    "DEFAULT_DT",
    "DEFAULT_HORIZON",
    "DEFAULT_LEAD_IN",
    "DEFAULT_VEHICLE_SIZE",
    "build_scenario",
]

DEFAULT_DT = 0.1
#: risk horizon added after the conflict is resolved, s (riskcore's Table II horizon)
DEFAULT_HORIZON = 3.0
#: the longest scenario the builder makes, s (a conflict taking longer is refused)
MAX_DURATION = 3600.0
DEFAULT_LEAD_IN = 2.5
#: (length, width) in m used for the ego and the cutter unless given
DEFAULT_VEHICLE_SIZE: tuple[float, float] = (4.5, 1.8)
GENERATOR = "scengen.sampler.builder/1"  # a format identifier: it stays what it was


def _size(value: Any, name: str) -> tuple[float, float]:
    try:
        length, width = (float(v) for v in value)
    except (TypeError, ValueError):
        raise BuilderError(f"{name}: expected (length, width) in m, got {value!r}") from None
    if not (math.isfinite(length) and math.isfinite(width) and length > 0 and width > 0):
        raise BuilderError(f"{name}: length and width must be positive m, got {value!r}")
    return length, width


def _positive(value: Any, name: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise BuilderError(f"{name}: expected a number of {unit}, got {value!r}")
    x = float(value)
    if not (math.isfinite(x) and x > 0):
        raise BuilderError(f"{name}: must be a positive finite number of {unit}, got {value!r}")
    return x


def _time_grid(n_steps: int, dt: float) -> NDArray[np.float64]:
    """``0, dt, ..., n_steps dt`` in s, each the float nearest its decimal value (3 x 0.1 is
    0.30000000000000004 in floating point; exported files should read 0.3)."""
    return np.round(np.arange(n_steps + 1, dtype=np.float64) * dt, 12)


def build_scenario(
    params: Mapping[str, float] | CutInParams,
    *,
    seed: int | None = None,
    dt: float = DEFAULT_DT,
    duration: float | None = None,
    lead_in: float = DEFAULT_LEAD_IN,
    lane_width: float = DEFAULT_LANE_WIDTH,
    ego_size: tuple[float, float] = DEFAULT_VEHICLE_SIZE,
    cutter_size: tuple[float, float] = DEFAULT_VEHICLE_SIZE,
    provenance: Mapping[str, Any] | None = None,
) -> ConcreteScenario:
    """Turn one cut-in parameter vector into a concrete scenario.

    Parameters
    ----------
    params : mapping of str to float, or CutInParams
        The vector of ``PARAM_NAMES`` in SI units (extra keys are ignored).
    seed : int, optional
        Seed of the sample set the vector came from; stored on the scenario.
    dt, lead_in : float
        Time step and time before the lateral motion starts, in s (``lead_in >= 0``).
    duration : float, optional
        Total length in s, a whole number of steps; default (None): until the conflict
        is resolved plus the risk horizon (module docstring). Shorter than the
        resolution is an error.
    lane_width : float
        Lane width in m; the marking is at ``lane_width / 2`` from either lane centre.
    ego_size, cutter_size : (float, float)
        (length, width) in m.
    provenance : mapping, optional
        Extra JSON-able entries merged into the scenario's provenance.

    Returns
    -------
    ConcreteScenario
        Objects: the ego (id ``"ego"``) and the cutter (id ``"cutter"``), each with
        x, y, psi, v, a, yaw_rate on ``t`` of shape (round(duration / dt) + 1,).

    Raises
    ------
    BuilderError
        Invalid settings, an invalid vector, or a vector that does not cross the marking.
    """
    p = _vector(params)
    dt = _positive(dt, "dt", "s")
    if duration is not None:
        duration = _positive(duration, "duration", "s")
    lane_width = _positive(lane_width, "lane_width", "m")
    lead_in = _lead_in(lead_in, duration)
    ego_len, ego_wid = _size(ego_size, "ego_size")
    cut_len, cut_wid = _size(cutter_size, "cutter_size")
    if p.p_y1 == 0.0:
        raise BuilderError("params.p_y1: is 0, the cutter would not change lanes")
    path = trajectory(p)  # integrated once: the crossing and both grids below use it
    tau_c, v_ego = _crossing(p, path, lane_width)
    geometry = _Geometry(p, path, lead_in, tau_c, v_ego, lane_width, ego_len, ego_wid,
                         cut_len, cut_wid)
    # after t_settle nothing changes speed or heading: the resolution is exact from there
    t_settle, n_settle = _settling(p, lead_in, dt)
    t_pre = _time_grid(n_settle, dt)
    ego_pre, cut_pre = geometry.tracks(t_pre)
    t_res, how = conflict_resolution(t_pre, ego_pre, cut_pre)
    n_steps = _steps(duration, dt, lead_in, t_res, how, t_settle, n_settle)
    t = _time_grid(n_steps, dt)
    ego, cutter = geometry.tracks(t)
    prov: dict[str, Any] = {
        "generator": GENERATOR,
        "lead_in": float(lead_in),
        "lane_width": lane_width,
        "t_cross": lead_in + tau_c,
        "t_resolved": t_res,
        "resolution": how,
        "v_ego": v_ego,
        "cutter_start_side": "right" if p.p_y1 > 0 else "left",
    }
    if provenance:
        prov.update(dict(provenance))
    return ConcreteScenario(t=t, ego=ego, objects=(cutter,), params=p.as_dict(), seed=seed,
                            provenance=prov)


# the steps of build_scenario, in its order
def _vector(params: Mapping[str, float] | CutInParams) -> CutInParams:
    """The parameter vector, checked."""
    if isinstance(params, CutInParams):
        return params
    if not isinstance(params, Mapping):
        raise BuilderError(f"params: expected a mapping of {PARAM_NAMES}, got {params!r}")
    try:
        return CutInParams.from_mapping(params)
    except (CutInParamError, TypeError, ValueError) as exc:
        raise BuilderError(f"params: {exc}") from None


def _lead_in(lead_in: float, duration: float | None) -> float:
    """The lead-in as a float in [0, duration)."""
    if isinstance(lead_in, bool) or not isinstance(lead_in, int | float) or not (
            float(lead_in) >= 0.0 and math.isfinite(float(lead_in))):
        raise BuilderError(f"lead_in: must be a finite number >= 0 s, got {lead_in!r}")
    lead_in = float(lead_in)
    if duration is not None and not lead_in < duration:
        raise BuilderError(f"lead_in: must be in [0, duration) s, got {lead_in!r}")
    return lead_in


def _crossing(p: CutInParams, path: CutInTrajectory,
              lane_width: float) -> tuple[float, float]:
    """The cutter's crossing time of the marking (from the start of its lateral motion)
    and the ego's speed, which meets the vector's dv there."""
    try:
        tau_c = path.crossing_time(lane_width / 2.0)
    except CutInParamError as exc:
        raise BuilderError(f"params: {exc}") from None
    v_cut_c = float(speed(p, tau_c))
    v_ego = v_cut_c + p.dv
    if not v_ego > 0:
        raise BuilderError(
            f"params: ego speed v_cutter(t_cross) + dv = {v_cut_c:.3f} + {p.dv:.3f} m/s "
            "is not positive"
        )
    return tau_c, v_ego


def _settling(p: CutInParams, lead_in: float, dt: float) -> tuple[float, int]:
    """When the cutter's lane change and pulse are over, and the steps until then."""
    pulse_end = p.p_a2 + p.p_a3 if p.p_a3 > 0 else 0.0
    t_settle = lead_in + max(2.0 * p.p_t, pulse_end, 0.0)
    if t_settle > MAX_DURATION:
        raise BuilderError(
            f"params: the cutter's lane change and acceleration pulse last until "
            f"{t_settle:.1f} s; scenarios are at most {MAX_DURATION:.0f} s")
    return t_settle, math.ceil(t_settle / dt - 1e-9) + 1


def _steps(duration: float | None, dt: float, lead_in: float, t_res: float, how: str,
           t_settle: float, n_settle: int) -> int:
    """The scenario's number of steps: the asked duration, checked against the conflict's
    resolution and the cutter's settling, or (None) until the resolution plus the risk
    horizon."""
    need = t_res - 1e-9 * max(1.0, t_res)
    if duration is None:
        # also until the cutter's motion has settled: a reacting ego (the criticality
        # record's reference drivers) meets the cutter later than the scripted one does
        duration = max(t_res + DEFAULT_HORIZON, n_settle * dt, lead_in + dt)
        n_steps = math.ceil(duration / dt - 1e-9)
    else:
        n_steps = round(duration / dt)
        if n_steps < 1 or abs(n_steps * dt - duration) > 1e-9 * max(duration, 1.0):
            raise BuilderError(
                f"duration: {duration} s is not a whole number of steps of {dt} s")
        if n_steps * dt < need:
            raise BuilderError(
                f"duration: {duration} s ends before the conflict is resolved ({how}) at "
                f"{t_res:.2f} s; ask for at least that or leave duration out (adaptive)")
        if n_steps * dt < t_settle - 1e-9 * max(1.0, t_settle):
            # after the end the motion is continued at constant velocity: a cut-off pulse
            # would change what the reacting reference drivers of the criticality meet
            raise BuilderError(
                f"duration: {duration} s ends before the cutter's lane change and "
                f"acceleration pulse are over at {t_settle:.2f} s; ask for at least that or "
                "leave duration out (adaptive)")
    if n_steps * dt > MAX_DURATION or n_steps > 100_000:
        raise BuilderError(
            f"params: the conflict is resolved ({how}) only at {t_res:.1f} s; scenarios "
            f"are at most {MAX_DURATION:.0f} s and 100000 steps")
    return n_steps


class _Geometry:
    """The ego and cutter tracks of one vector on any time grid (module docstring)."""

    def __init__(self, p: CutInParams, path: CutInTrajectory, lead_in: float, tau_c: float,
                 v_ego: float, lane_width: float, ego_len: float, ego_wid: float,
                 cut_len: float, cut_wid: float) -> None:
        self.p = p
        self.path = path
        self.lead_in = lead_in
        self.tau_c = tau_c
        self.v_ego = v_ego
        self.y_start = -lane_width if p.p_y1 > 0 else lane_width
        self.ego_size = (ego_len, ego_wid)
        self.cut_size = (cut_len, cut_wid)

    def tracks(self, t: np.ndarray) -> tuple[Track, Track]:
        p = self.p
        tau = t - self.lead_in
        # one integration: the crossing point is consistent with the samples
        m = self.path.motion(np.concatenate([tau, [self.tau_c]]))
        if (m.v[:-1] < 0).any():
            raise BuilderError("params: the cutter's speed becomes negative within the "
                               "scenario")
        x_rel = m.x[:-1]
        x_rel_c = float(m.x[-1])
        t_c = self.lead_in + self.tau_c
        ego_len, ego_wid = self.ego_size
        cut_len, cut_wid = self.cut_size
        x_cut0 = p.gap + 0.5 * (cut_len + ego_len) + self.v_ego * t_c - x_rel_c
        ego = Track(
            id="ego", length=ego_len, width=ego_wid,
            x=self.v_ego * t, y=np.zeros_like(t), psi=np.zeros_like(t),
            v=np.full_like(t, self.v_ego), a=np.zeros_like(t), yaw_rate=np.zeros_like(t),
        )
        cutter = Track(
            id="cutter", length=cut_len, width=cut_wid,
            x=x_cut0 + x_rel, y=self.y_start + m.y[:-1], psi=m.psi[:-1].copy(),
            v=m.v[:-1].copy(), a=m.a[:-1].copy(), yaw_rate=m.yaw_rate[:-1].copy(),
        )
        return ego, cutter
