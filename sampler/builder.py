"""Parameter vector -> concrete scenario (the geometry of one sampled cut-in).

Scenario time ``t`` runs from 0 to ``duration`` in steps of ``dt`` (default 0 ... 10 s,
0.1 s, 101 steps). The cutter's lateral motion starts at ``t = lead_in`` (default 2.5 s),
so the kinematic model's own time is ``tau = t - lead_in``.

Geometry (road frame: x along the road, y to the left, positions are vehicle centres):

* Ego: centre of its lane, ``y = 0``, heading 0, constant speed
  ``v_ego = v_cutter(tau_c) + dv``, ``x_ego(t) = v_ego t`` (it starts at x = 0).
* Cutter: starts at the centre of the adjacent lane on the side given by the sign of
  ``p_y1`` (``p_y1 > 0`` moves left, so it starts on the right, ``y = -lane_width``;
  ``p_y1 < 0`` starts at ``y = +lane_width``) and moves by
  ``datasets.cutin_model.motion``: yaw rate ``p_y1 sin(pi tau / p_t)``, the acceleration
  pulse ``(p_a1, p_a2, p_a3)``, speed ``p_v0`` at ``tau = 0``. Before ``tau = 0`` it drives
  straight (at constant speed unless the pulse starts earlier).
* Crossing moment ``tau_c = crossing_time(p, lane_width / 2)``: the cutter's centre is on
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

from datasets.cutin_model import (
    DEFAULT_LANE_WIDTH,
    PARAM_NAMES,
    CutInParamError,
    CutInParams,
    crossing_time,
    motion,
    speed,
)
from riskcore.scenario import ConcreteScenario, Track
from sampler._exceptions import BuilderError

__all__ = [
    "DEFAULT_DT",
    "DEFAULT_DURATION",
    "DEFAULT_LEAD_IN",
    "DEFAULT_VEHICLE_SIZE",
    "build_scenario",
]

DEFAULT_DT = 0.1
DEFAULT_DURATION = 10.0
DEFAULT_LEAD_IN = 2.5
#: (length, width) in m used for the ego and the cutter unless given
DEFAULT_VEHICLE_SIZE: tuple[float, float] = (4.5, 1.8)
GENERATOR = "scengen.sampler.builder/1"


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


def build_scenario(
    params: Mapping[str, float] | CutInParams,
    *,
    seed: int | None = None,
    dt: float = DEFAULT_DT,
    duration: float = DEFAULT_DURATION,
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
    dt, duration, lead_in : float
        Time step, total length and time before the lateral motion starts, in s.
        ``lead_in`` must lie in ``[0, duration)``.
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
    if isinstance(params, CutInParams):
        p = params
    else:
        if not isinstance(params, Mapping):
            raise BuilderError(f"params: expected a mapping of {PARAM_NAMES}, got {params!r}")
        try:
            p = CutInParams.from_mapping(params)
        except (CutInParamError, TypeError, ValueError) as exc:
            raise BuilderError(f"params: {exc}") from None
    dt = _positive(dt, "dt", "s")
    duration = _positive(duration, "duration", "s")
    lane_width = _positive(lane_width, "lane_width", "m")
    if isinstance(lead_in, bool) or not isinstance(lead_in, int | float) or not (
            0.0 <= float(lead_in) < duration):
        raise BuilderError(f"lead_in: must be in [0, duration) s, got {lead_in!r}")
    n_steps = round(duration / dt)
    if n_steps < 1 or abs(n_steps * dt - duration) > 1e-9 * max(duration, 1.0):
        raise BuilderError(f"duration: {duration} s is not a whole number of steps of {dt} s")
    if n_steps > 100_000:
        raise BuilderError(f"duration / dt = {n_steps} steps: too many (at most 100000)")
    ego_len, ego_wid = _size(ego_size, "ego_size")
    cut_len, cut_wid = _size(cutter_size, "cutter_size")
    if p.p_y1 == 0.0:
        raise BuilderError("params.p_y1: is 0, the cutter would not change lanes")
    try:
        tau_c = crossing_time(p, lane_width / 2.0)
    except CutInParamError as exc:
        raise BuilderError(f"params: {exc}") from None

    t = np.arange(n_steps + 1, dtype=np.float64) * dt
    tau = t - float(lead_in)
    # one call, one integration grid: the crossing point is consistent with the samples
    m = motion(p, np.concatenate([tau, [tau_c]]))
    x_rel, y_rel = m.x[:-1], m.y[:-1]
    x_rel_c = float(m.x[-1])
    v_cut_c = float(speed(p, tau_c))
    v_ego = v_cut_c + p.dv
    if not v_ego > 0:
        raise BuilderError(
            f"params: ego speed v_cutter(t_cross) + dv = {v_cut_c:.3f} + {p.dv:.3f} m/s "
            "is not positive"
        )
    if (m.v[:-1] < 0).any():
        raise BuilderError("params: the cutter's speed becomes negative within the scenario")
    t_c = float(lead_in) + tau_c
    x_cut0 = p.gap + 0.5 * (cut_len + ego_len) + v_ego * t_c - x_rel_c
    y_start = -lane_width if p.p_y1 > 0 else lane_width

    ego = Track(
        id="ego", length=ego_len, width=ego_wid,
        x=v_ego * t, y=np.zeros_like(t), psi=np.zeros_like(t), v=np.full_like(t, v_ego),
        a=np.zeros_like(t), yaw_rate=np.zeros_like(t),
    )
    cutter = Track(
        id="cutter", length=cut_len, width=cut_wid,
        x=x_cut0 + x_rel, y=y_start + y_rel, psi=m.psi[:-1].copy(), v=m.v[:-1].copy(),
        a=m.a[:-1].copy(), yaw_rate=m.yaw_rate[:-1].copy(),
    )
    prov: dict[str, Any] = {
        "generator": GENERATOR,
        "lead_in": float(lead_in),
        "lane_width": lane_width,
        "t_cross": t_c,
        "v_ego": v_ego,
        "cutter_start_side": "right" if p.p_y1 > 0 else "left",
    }
    if provenance:
        prov.update(dict(provenance))
    return ConcreteScenario(t=t, ego=ego, objects=(cutter,), params=p.as_dict(), seed=seed,
                            provenance=prov)
