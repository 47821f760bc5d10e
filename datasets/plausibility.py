"""Plausibility of an extracted cut-in parameter table: catches data in the wrong units.

A file whose speeds are in km/h or whose positions are in mm still extracts (the
extraction has no way to know), but gives a model of impossible traffic: median ego speeds
of 99 m/s, gaps of 31 km. ``implausible(table)`` compares the *medians* of the table's
columns with generous ranges for road traffic and returns one message per column outside
its range, saying what unit mistake it looks like. Medians, so a few odd events do not
trip it; ranges, so that any real highway or urban data set passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd


@dataclass(frozen=True)
class Range:
    column: str
    unit: str
    low: float
    high: float
    what: str
    hint: str


#: the median of each column must lie in [low, high]
RANGES: tuple[Range, ...] = (
    Range("v_ego", "m/s", 0.5, 60.0, "ego speed",
          "speeds in km/h? (60 m/s = 216 km/h)"),
    Range("p_v0", "m/s", 0.5, 60.0, "cutter speed",
          "speeds in km/h? (60 m/s = 216 km/h)"),
    Range("gap", "m", 0.1, 300.0, "gap at the cut-in",
          "positions in mm or cm?"),
    Range("p_t", "s", 0.2, 30.0, "lane-change duration",
          "times in ms, or the wrong sampling rate?"),
    Range("lane_width", "m", 2.0, 6.0, "lane width",
          "lane width in mm or cm?"),
)


def implausible(table: pd.DataFrame) -> list[str]:
    """One message per column whose median lies outside its plausible range (``RANGES``);
    empty when the table looks like road traffic in SI units."""
    problems = []
    for r in RANGES:
        if r.column not in table.columns:
            continue
        values = pd.to_numeric(table[r.column], errors="coerce")
        values = values[values.map(lambda v: math.isfinite(v))]
        if values.empty:
            continue
        median = float(values.abs().median())
        if not r.low <= median <= r.high:
            problems.append(f"median {r.what} {r.column} = {median:.4g} {r.unit} is outside "
                            f"the plausible {r.low:g}..{r.high:g} {r.unit}: {r.hint}")
    return problems
