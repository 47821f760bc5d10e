"""SQL aggregates of a catalogue's criticality columns for the dashboard's view 3.

Histograms are counted by the database (one ``SUM(CASE …)`` per bin in one query per
histogram, portable between SQLite and PostgreSQL), so a catalogue of any size costs a few
scans of its own rows and no row is sent to Python; only the TTC-against-btn scatter reads
four narrow columns (index, TTC, btn, class) to thin them (``aggregate.thin_scatter``).

The counting rule is numpy's (``aggregate.histogram``): bins are closed on the left, the
last one also on the right; +inf, -inf and null are not binned but counted.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sqlalchemy import and_, case, func, select
from sqlalchemy.orm import Session

from app.db.models import ScenarioRow

__all__ = ["column", "column_histogram", "finite_range", "scatter_columns", "top_rows"]


def column(name: str) -> Any:
    """The scenario column of a criticality field (``class`` is ``class_`` in the ORM)."""
    return ScenarioRow.class_ if name == "class" else getattr(ScenarioRow, name)


def _finite(col: Any) -> Any:
    return and_(col.is_not(None), col > -math.inf, col < math.inf)


def finite_range(session: Session, catalogue_id: str, col: Any,
                 where: Sequence[Any] = ()) -> tuple[float, float] | None:
    """(min, max) of a column's finite values among the rows matching ``where``; None
    when there is none."""
    lo, hi = session.execute(select(func.min(col), func.max(col)).where(
        ScenarioRow.catalogue_id == catalogue_id, _finite(col), *where)).one()
    return None if lo is None else (float(lo), float(hi))


def column_histogram(session: Session, catalogue_id: str, col: Any, edges: ArrayLike,
                     where: Sequence[Any] = ()) -> dict[str, Any]:
    """A histogram of a column over ``edges`` among the rows matching ``where``, counted
    in SQL.

    Returns the keys of ``aggregate.histogram`` (``edges``, ``counts``, ``density``, ``n``,
    ``n_finite``, ``below``, ``above``, ``n_nonfinite``) and ``n_inf`` (+inf), ``n_null``
    (no value: not scored or not defined).
    """
    e = [float(v) for v in np.asarray(edges, dtype=np.float64).ravel()]
    if len(e) < 2 or any(b <= a for a, b in itertools.pairwise(e)):
        raise ValueError("edges must be strictly increasing, at least two")

    def count(cond: Any) -> Any:
        return func.coalesce(func.sum(case((cond, 1), else_=0)), 0)

    last = len(e) - 2
    bins = [count(and_(col >= lo, col <= hi if i == last else col < hi))
            for i, (lo, hi) in enumerate(itertools.pairwise(e))]
    extra = [func.count(), count(_finite(col)), count(col == math.inf),
             count(col.is_(None)), count(and_(_finite(col), col < e[0])),
             count(and_(_finite(col), col > e[-1]))]
    values = session.execute(select(*bins, *extra).where(
        ScenarioRow.catalogue_id == catalogue_id, *where)).one()
    counts = [int(v) for v in values[:len(bins)]]
    n, n_finite, n_inf, n_null, below, above = (int(v) for v in values[len(bins):])
    widths = np.diff(np.asarray(e))
    density = (np.asarray(counts) / (n_finite * widths)) if n_finite else np.zeros_like(widths)
    return {"edges": e, "counts": counts, "density": [float(d) for d in density], "n": n,
            "n_finite": n_finite, "below": below, "above": above,
            "n_nonfinite": n - n_finite, "n_inf": n_inf, "n_null": n_null}


def scatter_columns(session: Session, catalogue_id: str) -> dict[str, Any]:
    """Index, TTC, btn and class of the scored scenarios (btn not null), in index order,
    as arrays (TTC null = +inf: an opening gap)."""
    rows = session.execute(
        select(ScenarioRow.idx, ScenarioRow.ttc, ScenarioRow.btn, ScenarioRow.class_)
        .where(ScenarioRow.catalogue_id == catalogue_id, ScenarioRow.btn.is_not(None))
        .order_by(ScenarioRow.idx)).all()
    return {
        "idx": np.array([r[0] for r in rows], dtype=np.int64),
        "ttc": np.array([math.inf if r[1] is None else r[1] for r in rows], dtype=np.float64),
        "btn": np.array([r[2] for r in rows], dtype=np.float64),
        "class": [r[3] for r in rows],
    }


#: the columns of the "riskiest" table
TOP_FIELDS = ("btn", "a_req", "class", "ttr_true", "ttr_manoeuvre", "ttc", "t_p",
              "r157_cc_collision", "r157_cc_impact_speed", "support")


def top_rows(session: Session, catalogue_id: str, limit: int) -> list[dict[str, Any]]:
    """The ``limit`` scored scenarios with the largest btn (+inf first; ties: lowest
    index), with the ``TOP_FIELDS``."""
    cols = [column(name) for name in TOP_FIELDS]
    rows = session.execute(
        select(ScenarioRow.idx, *cols)
        .where(ScenarioRow.catalogue_id == catalogue_id, ScenarioRow.btn.is_not(None))
        .order_by(ScenarioRow.btn.desc(), ScenarioRow.idx).limit(limit)).all()
    return [{"index": int(r[0]), **dict(zip(TOP_FIELDS, r[1:], strict=True))} for r in rows]
