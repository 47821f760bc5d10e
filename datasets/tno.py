"""Converter of the TNO cut-in data (de Gelder et al., 2021; MIT) to the ego-centric format.

Source encoding (``../shared/data/tno-cutin/README.md``): each scenario links an ego and a
target vehicle to activities; each activity holds B-splines over normalised time
tn in [0, 1] between its start and end events (recording clock, s):

- target ``LON_TARGET`` = [vabs (m/s), dx (m)], chained over several activities;
- target ``LAT_TARGET`` = dy (m), the lane change only;
- ego ``SPEED`` = v (m/s), chained.

The ego ``LATERAL_POSITION`` ("lane keeping ego") is not used: its values (8-34) match the
ego speed, not a lateral position, so the ego is taken to keep its lane (``ego_y`` = NaN).

Conversion: splines are evaluated with ``scipy.interpolate.splev`` on a ``rate`` Hz grid
(default 10 Hz) from ``pre`` s before the lane change to ``post`` s after it (cut to the
span where both the target's and the ego's longitudinal activities exist). Outside the
lane change dy is held at its end values (the activity is the whole lateral motion).
``dx`` is read as the bumper-to-bumper distance (front of the ego to the rear of the
target, what the radar measures; de Gelder's simulations use it directly as the initial
gap), so ``target_dx = dx + (ego_length + target_length) / 2`` with the assumed sizes
``EGO_SIZE`` and ``TARGET_SIZE``; the gap is then independent of the assumed lengths.
The lane width is not in the data, so ``lane_width`` is NaN (extraction estimates it).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.interpolate import splev

from datasets import egocentric as ec
from datasets.errors import FormatError

__all__ = [
    "EGO_SIZE",
    "TARGET_SIZE",
    "PlausibilityLimits",
    "TnoConversion",
    "convert_tno",
]

FloatArray = NDArray[np.float64]

#: assumed (length, width) in m: the TNO data holds no sizes
EGO_SIZE = (4.6, 1.8)
TARGET_SIZE = (4.6, 1.8)


@dataclass(frozen=True)
class PlausibilityLimits:
    """An event outside these limits is reported and left out."""

    min_speed: float = 3.0  #: m/s, target and ego speed over the event
    max_lat_speed: float = 4.0  #: m/s, |d dy / dt| (3 m/s is already a fast lane change)
    min_duration: float = 1.0  #: s, shortest lane change
    min_displacement: float = 1.0  #: m, smallest |dy(end) - dy(start)|
    lane_width: float = 3.5  #: m, assumed (Dutch motorways); the marking is at |dy| = w / 2
    min_dx: float = 0.0  #: m, dx when the target crosses the marking must exceed this


@dataclass
class TnoConversion:
    """Result of :func:`convert_tno`."""

    frame: pd.DataFrame  #: ego-centric format, plausible events only
    rejected: list[tuple[str, str]]  #: (event_id, reason)
    n_scenarios: int


def _time(data: dict[str, Any], uid: Any) -> float:
    try:
        return float(data["event"][str(uid)]["conditions"]["time"])
    except (KeyError, TypeError, ValueError):
        raise FormatError(f"event {uid}: missing or bad conditions.time") from None


def _spline(params: Any, index: int | None, where: str) -> tuple[Any, Any, int]:
    try:
        knots, coefs, degree = params["knots"], params["coefficients"], params["degree"]
        if index is not None:
            knots, coefs, degree = knots[index], coefs[index], degree[index]
        return (np.asarray(knots, dtype=np.float64), np.asarray(coefs, dtype=np.float64),
                int(degree))
    except (KeyError, TypeError, IndexError, ValueError):
        raise FormatError(f"{where}: bad B-spline parameters") from None


def _chain(
    data: dict[str, Any], acts: list[dict[str, Any]], index: int | None, t: FloatArray
) -> FloatArray:
    """Evaluate chained activities at t (NaN where none covers t; later ones win)."""
    out = np.full(t.shape, np.nan)
    for act in sorted(acts, key=lambda a: _time(data, a["start"]["uid"])):
        t0 = _time(data, act["start"]["uid"])
        t1 = _time(data, act["end"]["uid"])
        if t1 <= t0:
            continue
        inside = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        if not inside.any():
            continue
        tck = _spline(act["parameters"], index, f"activity {act.get('id')}")
        tn = np.clip((t[inside] - t0) / (t1 - t0), 0.0, 1.0)
        out[inside] = splev(tn, tck)
    return out


def _state(data: dict[str, Any], act: dict[str, Any]) -> str:
    cat = data["activity_category"].get(str(act["category"]["uid"]), {})
    return str(cat.get("state", {}).get("name", ""))


def convert_tno(
    path: str | Path, *, rate: float = 10.0, pre: float = 3.0, post: float = 3.0,
    limits: PlausibilityLimits | None = None,
) -> TnoConversion:
    """Convert TNO's ``cut-in.json`` into the ego-centric format.

    Parameters
    ----------
    path : str or Path
        The JSON file.
    rate : float
        Sampling rate of the output in Hz (>= 10 recommended).
    pre, post : float
        Seconds kept before the start and after the end of the lane change.
    limits : PlausibilityLimits, optional

    Returns
    -------
    TnoConversion
        Event ids are ``tno-NNN`` (1-based, in the file's scenario order).
    """
    limits = limits or PlausibilityLimits()
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        data = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise FormatError(f"{p}: not readable JSON ({exc})") from None
    for key in ("scenario", "activity", "activity_category", "event"):
        if not isinstance(data.get(key), dict):
            raise FormatError(f"{p}: missing top-level key {key!r}")
    frames: list[pd.DataFrame] = []
    rejected: list[tuple[str, str]] = []
    for k, (sid, sc) in enumerate(data["scenario"].items(), start=1):
        event_id = f"tno-{k:03d}"
        try:
            frame, reason = _convert_one(data, sc, event_id, rate, pre, post, limits)
        except (KeyError, TypeError, ValueError) as exc:
            frame, reason = None, f"malformed scenario {sid}: {exc}"
        if frame is None:
            rejected.append((event_id, reason))
        else:
            frames.append(frame)
    if not frames:
        raise FormatError(f"{p}: no plausible cut-in events")
    out = pd.concat(frames, ignore_index=True)
    return TnoConversion(ec.validate_egocentric(out, where=str(p)), rejected,
                         len(data["scenario"]))


def _convert_one(
    data: dict[str, Any], sc: dict[str, Any], event_id: str, rate: float, pre: float,
    post: float, limits: PlausibilityLimits,
) -> tuple[pd.DataFrame | None, str]:
    names = {int(a["uid"]): a["name"] for a in sc["actors"]}
    ego_uid = next(u for u, n in names.items() if n == "ego vehicle")
    by_actor: dict[str, dict[str, list[dict[str, Any]]]] = {"ego": {}, "target": {}}
    for act_ref in sc["acts"]:
        act = data["activity"][str(act_ref["activity"])]
        who = "ego" if int(act_ref["actor"]) == ego_uid else "target"
        by_actor[who].setdefault(_state(data, act), []).append(act)
    lat = by_actor["target"].get("LAT_TARGET", [])
    lon = by_actor["target"].get("LON_TARGET", [])
    spd = by_actor["ego"].get("SPEED", [])
    if len(lat) != 1 or not lon or not spd:
        return None, "missing target lane change, target longitudinal or ego speed data"
    lc = lat[0]
    ts, te = _time(data, lc["start"]["uid"]), _time(data, lc["end"]["uid"])
    if te - ts < limits.min_duration:
        return None, f"lane change shorter than {limits.min_duration:g} s ({te - ts:.2f} s)"

    def span(acts: list[dict[str, Any]]) -> tuple[float, float]:
        return (min(_time(data, a["start"]["uid"]) for a in acts),
                max(_time(data, a["end"]["uid"]) for a in acts))

    lo = max(ts - pre, span(lon)[0], span(spd)[0])
    hi = min(te + post, span(lon)[1], span(spd)[1])
    if lo > ts + 1e-6 or hi < te - 1e-6:
        return None, "longitudinal data does not cover the whole lane change"
    n = int(np.floor((hi - lo) * rate + 1e-9)) + 1
    t = np.round(lo + np.arange(n) / rate, 6)
    dy_lc = _chain(data, lat, None, np.clip(t, ts, te))
    vabs = _chain(data, lon, 0, t)
    dx = _chain(data, lon, 1, t)
    v_ego = _chain(data, spd, None, t)
    for name, arr in (("target speed", vabs), ("dx", dx), ("ego speed", v_ego), ("dy", dy_lc)):
        if not np.isfinite(arr).all():
            return None, f"{name} has gaps between activities"
    if vabs.min() < limits.min_speed:
        return None, f"target speed near 0 (min {vabs.min():.2f} m/s)"
    if v_ego.min() < limits.min_speed:
        return None, f"ego speed near 0 (min {v_ego.min():.2f} m/s)"
    lat_speed = np.abs(np.gradient(dy_lc, t))
    if lat_speed.max() > limits.max_lat_speed:
        return None, (f"lateral speed {lat_speed.max():.2f} m/s above "
                      f"{limits.max_lat_speed:g} m/s")
    disp = float(dy_lc[-1] - dy_lc[0])
    if abs(disp) < limits.min_displacement:
        return None, f"lateral displacement {abs(disp):.2f} m below {limits.min_displacement:g} m"
    if abs(dy_lc[-1]) >= abs(dy_lc[0]):
        return None, "the target does not move towards the ego's lane"
    if abs(dy_lc[-1]) >= 0.5 * limits.lane_width:
        return None, (f"the target never crosses the lane marking (ends at |dy| = "
                      f"{abs(dy_lc[-1]):.2f} m, marking at {0.5 * limits.lane_width:g} m)")
    if abs(dy_lc[0]) <= 0.5 * limits.lane_width:
        return None, (f"the lane change starts inside the ego's lane (|dy| = "
                      f"{abs(dy_lc[0]):.2f} m)")
    k_cross = int(np.argmax(np.abs(dy_lc) < 0.5 * limits.lane_width))
    if dx[k_cross] <= limits.min_dx:
        return None, (f"target not ahead of the ego when it crosses the marking "
                      f"(dx {dx[k_cross]:.2f} m)")
    frame = pd.DataFrame({
        ec.EVENT_ID: event_id,
        ec.T: t,
        ec.EGO_V: v_ego,
        ec.TARGET_DX: dx + 0.5 * (EGO_SIZE[0] + TARGET_SIZE[0]),
        ec.TARGET_DY: dy_lc,
        ec.TARGET_V: vabs,
        ec.EGO_LENGTH: EGO_SIZE[0],
        ec.EGO_WIDTH: EGO_SIZE[1],
        ec.TARGET_LENGTH: TARGET_SIZE[0],
        ec.TARGET_WIDTH: TARGET_SIZE[1],
        ec.EGO_Y: np.nan,
        ec.LANE_WIDTH: limits.lane_width,
    })
    return frame, ""
