"""The ego-centric ("JARI-style") format for on-board sensor data.

One row per time step per event. An event is one recorded cut-in: the ego vehicle's own
speed plus the tracked target's position relative to the ego. Columns (SI units, road
frame of the ego: x forward along the road, y to the left; positions are vehicle centres):

=================  ======  =========  =================================================
column             unit    required   meaning
=================  ======  =========  =================================================
``event_id``       text    yes        event identifier (unique within a file)
``t``              s       yes        time; strictly increasing within an event
``ego_v``          m/s     yes        ego speed (>= 0)
``target_dx``      m       yes        target centre x minus ego centre x (longitudinal)
``target_dy``      m       yes        target centre y minus ego centre y (+ = target left)
``target_v``       m/s     yes        target absolute speed (>= 0)
``ego_length``     m       yes        ego length (> 0), constant within an event
``ego_width``      m       yes        ego width (> 0)
``target_length``  m       yes        target length (> 0)
``target_width``   m       yes        target width (> 0)
``ego_y``          m       no         ego lateral offset from its lane centre
                                      (NaN or absent: 0, the ego keeps its lane centre)
``lane_width``     m       no         lane width (NaN or absent: unknown, estimated
                                      from the fitted lateral displacement)
=================  ======  =========  =================================================

Other columns are kept by the readers and ignored by extraction. Files are CSV (``.csv``,
optionally compressed: ``.csv.gz``, ``.csv.bz2``, ``.csv.xz``) or Parquet (``.parquet``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from datasets.errors import FormatError
from riskcore import ConcreteScenario, Track

__all__ = [
    "EGO_COLUMNS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "egocentric_to_scenarios",
    "event_to_scenario",
    "read_egocentric",
    "scenario_to_egocentric",
    "validate_egocentric",
    "write_egocentric",
]


def _show(value: object) -> str:
    """A cell value for an error message: strings quoted, numbers plain."""
    if isinstance(value, str):
        return repr(value)
    item = getattr(value, "item", None)
    return str(item() if callable(item) else value)

EVENT_ID = "event_id"
T = "t"
EGO_V = "ego_v"
TARGET_DX = "target_dx"
TARGET_DY = "target_dy"
TARGET_V = "target_v"
EGO_LENGTH = "ego_length"
EGO_WIDTH = "ego_width"
TARGET_LENGTH = "target_length"
TARGET_WIDTH = "target_width"
EGO_Y = "ego_y"
LANE_WIDTH = "lane_width"

#: required columns, in file order
REQUIRED_COLUMNS: tuple[str, ...] = (
    EVENT_ID, T, EGO_V, TARGET_DX, TARGET_DY, TARGET_V,
    EGO_LENGTH, EGO_WIDTH, TARGET_LENGTH, TARGET_WIDTH,
)
#: optional columns (NaN = unknown)
OPTIONAL_COLUMNS: tuple[str, ...] = (EGO_Y, LANE_WIDTH)
#: every column of the format, in file order
EGO_COLUMNS: tuple[str, ...] = (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS)

_NON_NEGATIVE = (EGO_V, TARGET_V)
_POSITIVE = (EGO_LENGTH, EGO_WIDTH, TARGET_LENGTH, TARGET_WIDTH)
_CSV_SUFFIXES = (".csv", ".csv.gz", ".csv.bz2", ".csv.xz")


def _kind(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".parquet"):
        return "parquet"
    if name.endswith(_CSV_SUFFIXES):
        return "csv"
    raise FormatError(
        f"{path}: unknown file type; use .csv (optionally .gz/.bz2/.xz) or .parquet"
    )


def validate_egocentric(frame: pd.DataFrame, where: str = "ego-centric frame") -> pd.DataFrame:
    """Check a frame against the format and return it normalised.

    Normalised: ``event_id`` as str, numeric columns as float64, optional columns present
    (NaN when absent), rows sorted by event (first appearance) then time, index reset.

    Raises
    ------
    FormatError
        Naming ``where``, the column and the row (0-based data row) of the first problem.
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise FormatError(f"{where}: missing column(s) {', '.join(missing)}")
    if len(frame) == 0:
        raise FormatError(f"{where}: no rows")
    out = frame.copy()
    out.index = pd.RangeIndex(len(out))
    ids = out[EVENT_ID]
    if ids.isna().any():
        row = int(np.flatnonzero(ids.isna().to_numpy())[0])
        raise FormatError(f"{where}: column {EVENT_ID!r}, row {row}: missing event id")
    out[EVENT_ID] = ids.astype(str)
    for col in OPTIONAL_COLUMNS:
        if col not in out.columns:
            out[col] = np.nan
    for col in (c for c in EGO_COLUMNS if c != EVENT_ID):
        raw = out[col]
        values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64)
        bad_parse = np.isnan(values) & raw.notna().to_numpy()
        bad = bad_parse | np.isinf(values) if col in OPTIONAL_COLUMNS else ~np.isfinite(values)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise FormatError(
                f"{where}: column {col!r}, row {row}: value {_show(raw.iloc[row])} "
                "is not a finite number"
            )
        if col in _NON_NEGATIVE and (values < 0).any():
            row = int(np.flatnonzero(values < 0)[0])
            raise FormatError(f"{where}: column {col!r}, row {row}: speed {values[row]} < 0")
        if col in _POSITIVE and (values <= 0).any():
            row = int(np.flatnonzero(values <= 0)[0])
            raise FormatError(f"{where}: column {col!r}, row {row}: size {values[row]} <= 0")
        if col == LANE_WIDTH and (values <= 0).any():
            row = int(np.flatnonzero(values <= 0)[0])
            raise FormatError(f"{where}: column {col!r}, row {row}: lane width {values[row]} <= 0")
        out[col] = values
    order = pd.unique(out[EVENT_ID])
    rank = pd.Series(np.arange(len(order)), index=order)
    out["_rank"] = rank.loc[out[EVENT_ID].to_numpy()].to_numpy()
    out["_row"] = np.arange(len(out))
    out = out.sort_values(["_rank", T, "_row"], kind="stable")
    same = out["_rank"].to_numpy()[1:] == out["_rank"].to_numpy()[:-1]
    dt = np.diff(out[T].to_numpy())
    dup = same & (dt <= 0)
    if dup.any():
        row = int(out["_row"].to_numpy()[1:][dup][0])
        raise FormatError(
            f"{where}: column {T!r}, row {row}: time repeats within event "
            f"{out[EVENT_ID].to_numpy()[1:][dup][0]!r}"
        )
    counts = out.groupby("_rank", sort=True)[T].size().to_numpy()
    if (counts < 2).any():
        ev = order[int(np.flatnonzero(counts < 2)[0])]
        raise FormatError(f"{where}: event {ev!r} has fewer than 2 rows")
    return out.drop(columns=["_rank", "_row"]).reset_index(drop=True)


def read_egocentric(path: str | Path) -> pd.DataFrame:
    """Read an ego-centric file (CSV or Parquet) and validate it.

    Returns
    -------
    DataFrame
        One row per time step per event, the columns of EGO_COLUMNS first (plus any
        extra columns of the file), normalised as by :func:`validate_egocentric`.
    """
    p = Path(path)
    kind = _kind(p)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        frame = (pd.read_parquet(p) if kind == "parquet"
                 else pd.read_csv(p, dtype={EVENT_ID: str}))
    except (OSError, ValueError) as exc:
        raise FormatError(f"{p}: cannot read ({exc})") from None
    out = validate_egocentric(frame, where=str(p))
    extra = [c for c in out.columns if c not in EGO_COLUMNS]
    return out.loc[:, [*EGO_COLUMNS, *extra]]


def write_egocentric(frame: pd.DataFrame, path: str | Path) -> Path:
    """Validate ``frame`` and write it as CSV or Parquet (chosen by the file suffix).

    Floats are written losslessly (CSV with shortest round-trip repr), so reading the file
    back gives the same numbers bit for bit.
    """
    p = Path(path)
    kind = _kind(p)
    out = validate_egocentric(frame, where="frame to write")
    extra = [c for c in out.columns if c not in EGO_COLUMNS]
    out = out.loc[:, [*EGO_COLUMNS, *extra]]
    p.parent.mkdir(parents=True, exist_ok=True)
    if kind == "parquet":
        out.to_parquet(p, index=False, compression="zstd")
    else:
        out.to_csv(p, index=False)
    return p


def scenario_to_egocentric(
    scenario: ConcreteScenario, event_id: str, lane_width: float | None = None
) -> pd.DataFrame:
    """Express a concrete scenario in the ego-centric format.

    The ego is ``scenario.ego``, the target its first object. Positions are taken in the
    road frame: ``target_dx = x_target - x_ego``, ``target_dy = y_target - y_ego``,
    ``ego_y = y_ego``.

    Parameters
    ----------
    scenario : ConcreteScenario
        Needs at least one object.
    event_id : str
    lane_width : float, optional
        Lane width in m. None: ``scenario.provenance["lane_width"]`` when present (the
        sampler's builder records it), else the absolute lateral offset of the target from
        the ego at the first time step (the target starts at the centre of the
        neighbouring lane and the ego at the centre of its own).

    Returns
    -------
    DataFrame of shape (len(scenario.t), len(EGO_COLUMNS))
    """
    if not scenario.objects:
        raise FormatError("scenario: has no objects, so no target to describe")
    ego = scenario.ego
    tgt = scenario.objects[0]
    n = len(scenario.t)
    if lane_width is None:
        recorded = scenario.provenance.get("lane_width")
        if isinstance(recorded, int | float) and not isinstance(recorded, bool):
            lane_width = float(recorded)
        else:
            lane_width = float(abs(tgt.y[0] - ego.y[0]))
    if not np.isfinite(lane_width) or lane_width <= 0:
        raise FormatError(f"lane_width: must be a positive number of metres, got {lane_width}")
    return pd.DataFrame({
        EVENT_ID: [str(event_id)] * n,
        T: np.asarray(scenario.t, dtype=np.float64),
        EGO_V: ego.v,
        TARGET_DX: tgt.x - ego.x,
        TARGET_DY: tgt.y - ego.y,
        TARGET_V: tgt.v,
        EGO_LENGTH: np.full(n, ego.length),
        EGO_WIDTH: np.full(n, ego.width),
        TARGET_LENGTH: np.full(n, tgt.length),
        TARGET_WIDTH: np.full(n, tgt.width),
        EGO_Y: ego.y - ego.y[0],
        LANE_WIDTH: np.full(n, float(lane_width)),
    })


def event_to_scenario(event: pd.DataFrame) -> ConcreteScenario:
    """One recorded event (the rows of one ``event_id``) as a concrete scenario.

    The inverse of :func:`scenario_to_egocentric` up to what the format does not carry:

    * ego: x from the trapezoidal integral of ``ego_v`` (x = 0 at the first row),
      y = ``ego_y`` (0 where unknown), heading from its velocity;
    * target (object ``"cutter"``): x = ego x + ``target_dx``, y = ego y + ``target_dy``,
      speed ``target_v``, heading from its velocity (the format has none; the direction
      of motion is what a box drawn from a track follows);
    * time from 0 at the first row; ``provenance``: the event id, ``source:
      "egocentric"`` and ``lane_width`` when the column holds a finite value.

    ``event`` must be validated (:func:`validate_egocentric` or :func:`read_egocentric`)
    and hold one event, in time order.
    """
    ids = event[EVENT_ID].unique()
    if len(ids) != 1:
        raise FormatError(f"event: expected the rows of one event, got {len(ids)} events")
    t = event[T].to_numpy(np.float64)
    t = t - t[0]
    v = event[EGO_V].to_numpy(np.float64)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    y = np.nan_to_num(event[EGO_Y].to_numpy(np.float64), nan=0.0) \
        if EGO_Y in event else np.zeros_like(t)
    first = event.iloc[0]
    ego = Track("ego", float(first[EGO_LENGTH]), float(first[EGO_WIDTH]), x, y,
                _heading(t, x, y), v)
    xc = x + event[TARGET_DX].to_numpy(np.float64)
    yc = y + event[TARGET_DY].to_numpy(np.float64)
    cutter = Track("cutter", float(first[TARGET_LENGTH]), float(first[TARGET_WIDTH]), xc,
                   yc, _heading(t, xc, yc), event[TARGET_V].to_numpy(np.float64))
    provenance: dict[str, object] = {"source": "egocentric", "event_id": str(ids[0])}
    lw = float(first[LANE_WIDTH]) if LANE_WIDTH in event else float("nan")
    if np.isfinite(lw) and lw > 0:
        provenance["lane_width"] = lw
    return ConcreteScenario(t=t, ego=ego, objects=(cutter,), provenance=provenance)


def egocentric_to_scenarios(frame: pd.DataFrame) -> dict[str, ConcreteScenario]:
    """Every event of an ego-centric frame as a concrete scenario, keyed by event id
    (in the frame's order). See :func:`event_to_scenario`."""
    frame = validate_egocentric(frame)
    return {str(eid): event_to_scenario(ev)
            for eid, ev in frame.groupby(EVENT_ID, sort=False)}


def _heading(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Direction of motion from positions (central differences), rad."""
    return np.asarray(np.arctan2(np.gradient(y, t), np.gradient(x, t)), dtype=np.float64)
