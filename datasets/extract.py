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
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from datasets import egocentric as ec
from datasets.errors import DatasetError, ExtractionError, FormatError
from datasets.extract_rows import (
    PULSE_MARGIN,
    ExtractionResult,
    finish_row,
    motion_row,
    to_table,
)
from datasets.highd_extract import extract_recording
from datasets.table import empty_table

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
    row = motion_row(t, y, v_cut, lane_width=lane_width, pulse_margin=None)
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
    return finish_row(row, dx - half, v_ego, v_c)


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
    return ExtractionResult(to_table(rows), skipped)


def extract_egocentric(frame: pd.DataFrame, source: str = "egocentric") -> pd.DataFrame:
    """The parameter table of an ego-centric frame (events that fail are left out)."""
    return extract_egocentric_report(frame, source=source).table


# ---------------------------------------------------------------------------- highD

def extract_highd_report(recording: HighDRecording, progress: bool = False) -> ExtractionResult:
    """Extract every cut-in of a highD recording (see :mod:`datasets.highd_extract`)."""
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


