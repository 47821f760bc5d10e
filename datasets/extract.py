"""Cut-in extraction: measured motion -> the parameter table (one row per cut-in).

For every cut-in (DESIGN.md, docs/datasets.md):

1. the lateral model (p_y1, p_t, t0 and the start-lane position) is fitted by least squares
   to the cutter's lateral position (:func:`datasets.fit.fit_lateral`); t0 is the start of
   the lateral motion, i.e. t = 0 of the parameter vector;
2. the rectangular acceleration pulse (p_a1, p_a2, p_a3, and p_v0 = model speed at t0) is
   fitted by least squares to the cutter's speed (:func:`datasets.fit.fit_pulse`): over
   the whole event for ego-centric data (an event is cut around one cut-in), over
   [t0 - 2 s, t0 + 2 p_t + 2 s] of the track window for highD (``PULSE_MARGIN``);
3. the crossing moment is the first time the cutter's centre is half a lane width away
   from its start-lane centre (highD: the time its centre crosses the lane marking, linear
   interpolation between frames); ``dv = v_ego - v_cutter`` and the bumper-to-bumper
   ``gap`` are interpolated there, ``ttc = gap / dv`` (dv > 0) and ``thw = gap / v_ego``.

Entry points: :func:`extract_egocentric` (a frame in the ego-centric format),
:func:`extract_highd` (a :class:`datasets.highd.HighDRecording`) and :func:`extract_cutins`
(a file or directory path and a format name). Events that cannot be extracted are left
out and listed, with the reason, in :attr:`ExtractionResult.skipped`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from datasets import egocentric as ec
from datasets.cutin_model import ttc_from_gap_dv
from datasets.errors import DatasetError, ExtractionError, FormatError
from datasets.fit import fit_lateral, fit_pulse, max_lateral_speed
from datasets.table import TABLE_COLUMNS, empty_table, validate_table

if TYPE_CHECKING:
    from datasets.highd import HighDRecording

__all__ = [
    "PULSE_MARGIN",
    "ExtractionResult",
    "extract_cutins",
    "extract_egocentric",
    "extract_egocentric_report",
    "extract_highd",
    "extract_highd_report",
]

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


def _to_table(rows: list[dict[str, Any]]) -> pd.DataFrame:
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


def _motion_row(
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


def _finish_row(row: dict[str, Any], gap: float, v_ego: float, v_cut: float) -> dict[str, Any]:
    dv = v_ego - v_cut
    row.update({
        "dv": dv, "gap": gap, "ttc": float(ttc_from_gap_dv(gap, dv)),
        "thw": gap / v_ego if v_ego > 0 else float("inf"), "v_ego": v_ego,
    })
    if not np.isfinite(row["thw"]):
        raise ExtractionError("ego speed is 0 at the crossing moment: THW undefined")
    return row


# ---------------------------------------------------------------------------- ego-centric

def _extract_event(ev: pd.DataFrame) -> dict[str, Any]:
    t = ev[ec.T].to_numpy()
    ego_y = np.nan_to_num(ev[ec.EGO_Y].to_numpy(), nan=0.0)
    dy = ev[ec.TARGET_DY].to_numpy()
    y = ego_y + dy
    v_cut = ev[ec.TARGET_V].to_numpy()
    widths = ev[ec.LANE_WIDTH].to_numpy()
    finite = widths[np.isfinite(widths)]
    lane_width = float(finite[0]) if finite.size else None
    row = _motion_row(t, y, v_cut, lane_width=lane_width, pulse_margin=None)
    tc = row["t_cross"]
    if abs(y[-1]) >= abs(y[0]):
        raise ExtractionError(
            f"the target does not approach the ego laterally (|dy| {abs(y[0]):.2f} m -> "
            f"{abs(y[-1]):.2f} m): not a cut-in"
        )
    dx = float(np.interp(tc, t, ev[ec.TARGET_DX].to_numpy()))
    if dx <= 0:
        raise ExtractionError(
            f"the target is behind the ego at the crossing moment (dx {dx:.2f} m)"
        )
    half = 0.5 * (float(np.interp(tc, t, ev[ec.EGO_LENGTH].to_numpy()))
                  + float(np.interp(tc, t, ev[ec.TARGET_LENGTH].to_numpy())))
    v_ego = float(np.interp(tc, t, ev[ec.EGO_V].to_numpy()))
    v_c = float(np.interp(tc, t, v_cut))
    return _finish_row(row, dx - half, v_ego, v_c)


def extract_egocentric_report(
    frame: pd.DataFrame, source: str = "egocentric", progress: bool = False
) -> ExtractionResult:
    """Extract one cut-in per event of an ego-centric frame; list the events left out.

    Parameters
    ----------
    frame : DataFrame
        Ego-centric format (see :mod:`datasets.egocentric`); validated here.
    source : str
        Written into the ``source`` column.
    progress : bool
        Show a progress bar on stderr.
    """
    data = ec.validate_egocentric(frame, where=source)
    rows: list[dict[str, Any]] = []
    skipped: list[tuple[str, str]] = []
    groups: Iterable[tuple[Any, pd.DataFrame]] = data.groupby(ec.EVENT_ID, sort=False)
    if progress:
        from tqdm import tqdm

        groups = tqdm(groups, total=data[ec.EVENT_ID].nunique(), desc="extract", unit="event")
    for event_id, ev in groups:
        try:
            row = _extract_event(ev)
        except DatasetError as exc:  # one bad event never stops the file
            skipped.append((str(event_id), str(exc)))
            continue
        row.update({"source": source, "event_id": str(event_id), "ego_id": "",
                    "cutter_id": ""})
        rows.append(row)
    return ExtractionResult(_to_table(rows), skipped)


def extract_egocentric(frame: pd.DataFrame, source: str = "egocentric") -> pd.DataFrame:
    """The parameter table of an ego-centric frame (events that fail are left out)."""
    return extract_egocentric_report(frame, source=source).table


# ---------------------------------------------------------------------------- highD

def extract_highd_report(recording: HighDRecording, progress: bool = False) -> ExtractionResult:
    """Extract every cut-in of a highD recording (see :mod:`datasets.highd_extract`)."""
    from datasets.highd_extract import extract_recording

    return extract_recording(recording, progress=progress)


def extract_highd(recording: HighDRecording) -> pd.DataFrame:
    """The parameter table of a :class:`datasets.highd.HighDRecording`."""
    return extract_highd_report(recording).table


# ---------------------------------------------------------------------------- files

def extract_cutins(
    path: str | Path, fmt: Literal["highd", "egocentric"], progress: bool = False
) -> ExtractionResult:
    """Read ``path`` in format ``fmt`` and extract its cut-ins.

    Parameters
    ----------
    path : str or Path
        highD: a directory with ``XX_tracks.csv``, ``XX_tracksMeta.csv`` and
        ``XX_recordingMeta.csv`` (every recording in it is read) or the path of one of the
        three files. Ego-centric: a CSV or Parquet file.
    fmt : {"highd", "egocentric"}
    """
    p = Path(path)
    if fmt == "egocentric":
        frame = ec.read_egocentric(p)
        return extract_egocentric_report(frame, source=p.name, progress=progress)
    if fmt == "highd":
        from datasets import highd_columns as hc
        from datasets.highd import find_recordings, read_highd

        tables: list[pd.DataFrame] = []
        skipped: list[tuple[str, str]] = []
        seconds = metres = duration = 0.0
        names = []
        for prefix in find_recordings(p):
            rec = read_highd(prefix, progress=progress)
            res = extract_highd_report(rec, progress=progress)
            tables.append(res.table)
            skipped.extend(res.skipped)
            s, m = rec.driven()
            seconds += s
            metres += m
            duration += float(rec.recording_meta[hc.DURATION].iloc[0])
            names.append(rec.name)
        table = pd.concat(tables, ignore_index=True) if tables else empty_table()
        exposure = {"vehicle_hours": seconds / 3600.0, "vehicle_km": metres / 1000.0,
                    "recordings": names, "duration_hours": duration / 3600.0}
        return ExtractionResult(table, skipped, exposure)
    raise FormatError(f"format: expected 'highd' or 'egocentric', got {fmt!r}")


