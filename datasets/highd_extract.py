"""Cut-ins in a highD recording.

A cut-in (issue 3): vehicle C changes lane (its ``laneId`` changes between two frames),
and at the first frame in the new lane a vehicle E drives behind it in that lane
(``followingId`` of C) and has C as its new ``precedingId`` (it had another, or none, in
the frame before). E is the ego. A lane change with nobody behind is not a cut-in.

Per cut-in the fit window is the cutter's track around the lane change, cut at the
midpoints to its previous and next lane changes and to +-``WINDOW`` s; see
:mod:`datasets.extract` for the fits and the crossing moment (here: the time the cutter's
centre crosses the lane marking, from ``upperLaneMarkings``/``lowerLaneMarkings``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from datasets.errors import DatasetError, ExtractionError
from datasets.extract_rows import ExtractionResult, finish_row, motion_row, to_table
from datasets.highd import HighDRecording, road_frame

__all__ = ["WINDOW", "extract_recording", "find_cutins"]

#: seconds of track kept on each side of the lane change for the fits
WINDOW = 8.0


def find_cutins(road: pd.DataFrame) -> pd.DataFrame:
    """Lane changes and the cut-ins among them.

    Parameters
    ----------
    road : DataFrame
        :func:`datasets.highd.road_frame` output (sorted by id, frame).

    Returns
    -------
    DataFrame
        One row per lane change: ``cutter``, ``row`` (index into ``road`` of the first frame
        in the new lane), ``frame``, ``lane_from``, ``lane_to``, ``ego`` (0 when nobody is
        behind, i.e. not a cut-in), ``is_cutin``.
    """
    ids = road["id"].to_numpy()
    lane = road["lane_id"].to_numpy()
    frame = road["frame"].to_numpy()
    change = np.flatnonzero((ids[1:] == ids[:-1]) & (lane[1:] != lane[:-1])) + 1
    follower = road["following_id"].to_numpy()[change]
    pairs = pd.MultiIndex.from_arrays([ids, frame])
    lookup = pd.Series(road["preceding_id"].to_numpy(), index=pairs)
    lookup = lookup[~lookup.index.duplicated()]
    now = lookup.reindex(pd.MultiIndex.from_arrays([follower, frame[change]])).to_numpy()
    before = lookup.reindex(pd.MultiIndex.from_arrays([follower, frame[change] - 1])).to_numpy()
    is_cutin = (follower != 0) & (now == ids[change]) & (before != ids[change])
    return pd.DataFrame({
        "cutter": ids[change], "row": change, "frame": frame[change],
        "lane_from": lane[change - 1], "lane_to": lane[change],
        "ego": np.where(is_cutin, follower, 0), "is_cutin": is_cutin,
    })


def _interp(track: pd.DataFrame, t: float, col: str) -> float:
    ts = track["t"].to_numpy()
    if not ts[0] <= t <= ts[-1]:
        vid = int(track["id"].iloc[0])
        raise ExtractionError(f"vehicle {vid} is not recorded at t = {t:.2f} s")
    return float(np.interp(t, ts, track[col].to_numpy()))


def extract_recording(recording: HighDRecording, progress: bool = False) -> ExtractionResult:
    """Extract every cut-in of ``recording`` into the parameter table.

    ``source`` is the recording name (prefixed ``synthetic:`` for synthetic recordings),
    ``event_id`` is ``<name>-<cutter id>-<frame of the lane change>``, ``ego_id`` and
    ``cutter_id`` the highD track ids; times are ``frame / frameRate``.
    """
    road = road_frame(recording)
    events = find_cutins(road)
    source = f"synthetic:{recording.name}" if recording.is_synthetic else recording.name
    starts = np.flatnonzero(np.r_[True, road["id"].to_numpy()[1:] != road["id"].to_numpy()[:-1]])
    bounds = dict(zip(road["id"].to_numpy()[starts],
                      zip(starts, np.r_[starts[1:], len(road)], strict=True), strict=True))
    changes_by_id = events.groupby("cutter")["row"].apply(list).to_dict()
    rows: list[dict[str, Any]] = []
    skipped: list[tuple[str, str]] = []
    cutins: Any = events[events["is_cutin"]].itertuples(index=False)
    if progress:
        from tqdm import tqdm

        cutins = tqdm(cutins, total=int(events["is_cutin"].sum()), desc="cut-ins", unit="cut-in")
    fr = recording.frame_rate
    for ev in cutins:
        event_id = f"{recording.name}-{ev.cutter}-{ev.frame}"
        try:
            lo, hi = bounds[ev.cutter]
            others = [r for r in changes_by_id[ev.cutter] if r != ev.row]
            prev = max((r for r in others if r < ev.row), default=None)
            nxt = min((r for r in others if r > ev.row), default=None)
            a = max(lo, ev.row - int(WINDOW * fr), (prev + ev.row) // 2 if prev else lo)
            b = min(hi, ev.row + int(WINDOW * fr), (nxt + ev.row) // 2 if nxt else hi)
            cut = road.iloc[a:b]
            y_mark = recording.marking_road(int(ev.lane_from), int(ev.lane_to))
            t = cut["t"].to_numpy()
            v_cut = np.hypot(cut["vx"].to_numpy(), cut["vy"].to_numpy())
            row = motion_row(t, cut["y"].to_numpy(), v_cut,
                              lane_width=recording.lane_width(int(ev.lane_from)),
                              y_marking=y_mark)
            tc = row["t_cross"]
            e_lo, e_hi = bounds[ev.ego]
            ego = road.iloc[e_lo:e_hi]
            x_c = float(np.interp(tc, t, cut["x"].to_numpy()))
            x_e = _interp(ego, tc, "x")
            ego_v = np.hypot(ego["vx"].to_numpy(), ego["vy"].to_numpy())
            v_e = float(np.interp(tc, ego["t"].to_numpy(), ego_v))
            half = 0.5 * (float(cut["length"].iloc[0]) + float(ego["length"].iloc[0]))
            row = finish_row(row, x_c - x_e - half, v_e, float(np.interp(tc, t, v_cut)))
        except DatasetError as exc:  # one bad event never stops the recording
            skipped.append((event_id, str(exc)))
            continue
        row.update({"source": source, "event_id": event_id, "ego_id": str(ev.ego),
                    "cutter_id": str(ev.cutter)})
        rows.append(row)
    return ExtractionResult(to_table(rows), skipped)
