"""The parameter table: one row per extracted cut-in. Its columns are declared here once.

Columns (SI units, road frame; see docs/datasets.md for the full definitions):

- the parameter vector ``PARAM_NAMES`` of :mod:`datasets.cutin_model`
  (``p_y1 p_t p_a1 p_a2 p_a3 p_v0 dv gap``);
- ``ttc`` (s): gap / dv at the crossing moment when dv > 0, else +inf;
- ``thw`` (s): gap / v_ego at the crossing moment (bumper-to-bumper time headway);
- ``v_ego`` (m/s): ego speed at the crossing moment;
- ``side``: ``"left"`` or ``"right"``, the side of the ego the cutter comes from
  (``p_y1 > 0``, moving left, means it comes from the right);
- ``lane_width`` (m): width of the cutter's start lane (measured or estimated);
- ``max_lat_speed`` (m/s): largest measured lateral speed of the cutter in the fit window;
- ``resid_lat`` (m): RMS residual of the lateral-motion fit;
- ``resid_lon`` (m/s): RMS residual of the speed-pulse fit;
- ``source``: source file or data set name; ``event_id``: event id within the source;
- ``ego_id``, ``cutter_id``: vehicle ids (highD; empty strings for ego-centric data);
- ``t_start``, ``t_cross``, ``t_end`` (s, clock of the source): start of the lateral motion
  (fitted t = 0), crossing moment, end of the lateral motion (t_start + 2 p_t).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from datasets.cutin_model import PARAM_NAMES
from datasets.errors import FormatError

__all__ = [
    "CONTEXT_COLUMNS",
    "TABLE_COLUMNS",
    "TEXT_COLUMNS",
    "describe_table",
    "empty_table",
    "read_table",
    "validate_table",
    "write_table",
]


def _show(value: object) -> str:
    """A cell value for an error message: strings quoted, numbers plain."""
    if isinstance(value, str):
        return repr(value)
    item = getattr(value, "item", None)
    return str(item() if callable(item) else value)

#: derived and context columns, after the parameter vector
CONTEXT_COLUMNS: tuple[str, ...] = (
    "ttc",
    "thw",
    "v_ego",
    "side",
    "lane_width",
    "max_lat_speed",
    "resid_lat",
    "resid_lon",
    "source",
    "event_id",
    "ego_id",
    "cutter_id",
    "t_start",
    "t_cross",
    "t_end",
)

#: all columns of the parameter table, in order
TABLE_COLUMNS: tuple[str, ...] = (*PARAM_NAMES, *CONTEXT_COLUMNS)

#: columns holding text; every other column is float64
TEXT_COLUMNS: frozenset[str] = frozenset({"side", "source", "event_id", "ego_id", "cutter_id"})


def empty_table() -> pd.DataFrame:
    """A parameter table with no rows and the right columns and dtypes."""
    return pd.DataFrame(
        {c: pd.Series([], dtype=object if c in TEXT_COLUMNS else np.float64)
         for c in TABLE_COLUMNS}
    )


def validate_table(table: pd.DataFrame, where: str = "parameter table") -> pd.DataFrame:
    """Check that ``table`` has every column of TABLE_COLUMNS with usable values.

    Returns the table with its columns in canonical order and numeric columns as float64.
    Raises FormatError naming the column and the first bad row. ``ttc`` may be +inf;
    every other numeric column must be finite.
    """
    missing = [c for c in TABLE_COLUMNS if c not in table.columns]
    if missing:
        raise FormatError(f"{where}: missing column(s) {', '.join(missing)}")
    out = table.loc[:, list(TABLE_COLUMNS)].copy()
    for col in TABLE_COLUMNS:
        if col in TEXT_COLUMNS:
            out[col] = out[col].astype(str).astype(object)
            continue
        values = pd.to_numeric(out[col], errors="coerce").to_numpy(dtype=np.float64)
        ok = np.isfinite(values) | ((col == "ttc") & (values == np.inf))
        if not ok.all():
            row = int(np.flatnonzero(~ok)[0])
            raise FormatError(
                f"{where}: column {col!r}, row {row}: value {_show(table[col].iloc[row])} "
                "is not a finite number"
            )
        out[col] = values
    bad_side = ~out["side"].isin(["left", "right"])
    if bad_side.any():
        row = int(np.flatnonzero(bad_side.to_numpy())[0])
        raise FormatError(f"{where}: column 'side', row {row}: expected 'left' or 'right'")
    return out.reset_index(drop=True)


def write_table(table: pd.DataFrame, path: str | Path) -> Path:
    """Write a parameter table as ``.parquet`` or ``.csv`` (chosen by the suffix)."""
    p = Path(path)
    out = validate_table(table)
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.name.lower().endswith(".parquet"):
        out.to_parquet(p, index=False)
    elif p.name.lower().endswith((".csv", ".csv.gz")):
        out.to_csv(p, index=False)
    else:
        raise FormatError(f"{p}: unknown table file type; use .parquet or .csv")
    return p


def read_table(path: str | Path) -> pd.DataFrame:
    """Read and validate a parameter table written by :func:`write_table`."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        if p.name.lower().endswith(".parquet"):
            frame = pd.read_parquet(p)
        elif p.name.lower().endswith((".csv", ".csv.gz")):
            frame = pd.read_csv(p, dtype={c: str for c in TEXT_COLUMNS}, keep_default_na=False,
                                na_values=[""])
        else:
            raise FormatError(f"{p}: unknown table file type; use .parquet or .csv")
    except (OSError, ValueError) as exc:
        if isinstance(exc, FormatError):
            raise
        raise FormatError(f"{p}: cannot read ({exc})") from None
    return validate_table(frame, where=str(p))


def describe_table(table: pd.DataFrame) -> pd.DataFrame:
    """Summary statistics of every column: one row per column.

    Numeric columns: count of finite values, number of +inf (``ttc``), mean, std, min,
    quartiles, max over the finite values. Text columns: number of distinct values and the
    most frequent one with its count.
    """
    rows = []
    for col in TABLE_COLUMNS:
        s = table[col]
        if col in TEXT_COLUMNS:
            counts = s.astype(str).value_counts()
            top = f"{counts.index[0]} ({int(counts.iloc[0])})" if len(counts) else ""
            rows.append({"column": col, "count": len(s), "n_inf": 0, "unique": len(counts),
                         "top": top})
            continue
        x = s.to_numpy(dtype=np.float64)
        fin = x[np.isfinite(x)]
        row: dict[str, object] = {"column": col, "count": int(fin.size),
                                  "n_inf": int(np.isinf(x).sum()), "unique": None, "top": ""}
        if fin.size:
            q = np.percentile(fin, [0, 25, 50, 75, 100])
            row.update({"mean": float(fin.mean()),
                        "std": float(fin.std(ddof=1)) if fin.size > 1 else float("nan"),
                        "min": q[0], "25%": q[1], "50%": q[2], "75%": q[3], "max": q[4]})
        rows.append(row)
    cols = ["column", "count", "n_inf", "mean", "std", "min", "25%", "50%", "75%", "max",
            "unique", "top"]
    return pd.DataFrame(rows).reindex(columns=cols).set_index("column")
