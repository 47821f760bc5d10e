"""The rows of the parameter table from measured motion: the pieces every extractor shares
(the lateral and pulse fits, the crossing moment, the row's derived columns) and the
:class:`ExtractionResult` they return. The extractors are :mod:`datasets.extract`
(ego-centric data, files) and :mod:`datasets.highd_extract` (highD recordings).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from datasets.cutin_model import ttc_from_gap_dv
from datasets.errors import ExtractionError
from datasets.fit import fit_lateral, fit_pulse, max_lateral_speed
from datasets.table import TABLE_COLUMNS, empty_table, validate_table

__all__ = ["PULSE_MARGIN", "ExtractionResult", "finish_row", "motion_row", "to_table"]

FloatArray = NDArray[np.float64]

#: highD: seconds of speed data before t0 and after t0 + 2 p_t used by the pulse fit
PULSE_MARGIN = 2.0


@dataclass
class ExtractionResult:
    """The parameter table plus the events that were left out, with reasons."""

    table: pd.DataFrame
    skipped: list[tuple[str, str]] = field(default_factory=list)
    #: highD: the recordings' exposure per vehicle (``HighDRecording.driven``, summed):
    #: ``vehicle_hours``, ``vehicle_km``, ``recordings``, ``duration_hours``; else None
    exposure: dict[str, Any] | None = None


def to_table(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The validated parameter table of these rows (an empty table for none)."""
    if not rows:
        return empty_table()
    return validate_table(pd.DataFrame(rows, columns=list(TABLE_COLUMNS)))


def _crossing_time(t: FloatArray, y: FloatArray, y_marking: float, sign: float) -> float:
    """First time y crosses y_marking moving in direction ``sign`` (+1 = left).

    Linear interpolation between the bracketing samples. NaN when y never gets from the
    start side to the other side.
    """
    s = sign * (y - y_marking)
    before = s < 0
    if not before.any():
        return float("nan")
    first_before = int(np.argmax(before))
    after = np.flatnonzero(s[first_before:] >= 0)
    if after.size == 0:
        return float("nan")
    i = first_before + int(after[0])
    frac = -s[i - 1] / (s[i] - s[i - 1])
    return float(t[i - 1] + frac * (t[i] - t[i - 1]))


def motion_row(
    t: FloatArray, y: FloatArray, v_cut: FloatArray, *, lane_width: float | None,
    y_marking: float | None = None, pulse_margin: float | None = PULSE_MARGIN,
) -> dict[str, Any]:
    """Fit both models and find the crossing moment. Returns the cutter's part of a row.

    ``y`` is the cutter's lateral position in a lane-fixed frame. With ``y_marking`` the
    crossing moment is when y crosses it. Otherwise, with ``lane_width``, y is taken as
    relative to the ego's lane centre and the marking lies at sign(y_start) lane_width / 2;
    without it, the crossing is when |y - y_start| reaches half the fitted displacement.
    """
    lat = fit_lateral(t, y, v_cut)
    width = abs(lat.displacement) if lane_width is None else float(lane_width)
    if y_marking is None and lane_width is not None:
        y_marking = float(np.sign(lat.y_start)) * 0.5 * width
    sign = 1.0 if lat.p_y1 > 0 else -1.0
    if y_marking is None:
        y_marking = lat.y_start + sign * 0.5 * width
    if sign * (y_marking - lat.y_start) <= 0:
        raise ExtractionError(
            f"the cutter moves away from the lane marking at {y_marking:.2f} m "
            f"(starts at {lat.y_start:.2f} m): a cut-out, not a cut-in"
        )
    t_cross = _crossing_time(t, y, y_marking, sign)
    if not np.isfinite(t_cross):
        raise ExtractionError(
            f"the cutter never crosses the lane marking (lateral displacement "
            f"{lat.displacement:.2f} m, lane width {width:.2f} m)"
        )
    if pulse_margin is None:
        w = np.ones(t.shape, dtype=bool)
    else:
        lo, hi = lat.t0 - pulse_margin, lat.t0 + 2.0 * lat.p_t + pulse_margin
        w = (t >= lo) & (t <= hi)
    pulse = fit_pulse(t[w], v_cut[w], lat.t0)
    return {
        "p_y1": lat.p_y1, "p_t": lat.p_t, "p_a1": pulse.p_a1, "p_a2": pulse.p_a2,
        "p_a3": pulse.p_a3, "p_v0": pulse.p_v0,
        "side": "right" if lat.p_y1 > 0 else "left",
        "lane_width": width,
        "max_lat_speed": max_lateral_speed(t, y),
        "resid_lat": lat.rms, "resid_lon": pulse.rms,
        "t_start": lat.t0, "t_cross": t_cross, "t_end": lat.t0 + 2.0 * lat.p_t,
    }


def finish_row(row: dict[str, Any], gap: float, v_ego: float, v_cut: float) -> dict[str, Any]:
    """Complete a row with the crossing moment's gap and speeds: dv, gap, TTC, THW, v_ego."""
    dv = v_ego - v_cut
    row.update({
        "dv": dv, "gap": gap, "ttc": float(ttc_from_gap_dv(gap, dv)),
        "thw": gap / v_ego if v_ego > 0 else float("inf"), "v_ego": v_ego,
    })
    if not np.isfinite(row["thw"]):
        raise ExtractionError("ego speed is 0 at the crossing moment: THW undefined")
    return row
