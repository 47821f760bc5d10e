"""Server-side aggregation and downsampling: what keeps the dashboard's payload bounded.

Every plot of the dashboard gets a fixed-size summary, whatever the number of scenarios:

* histograms are binned here (``histogram``, ``shared_edges``): at most ``MAX_BINS`` bars;
* scatter plots are thinned here (``thin_scatter``): at most ``MAX_SCATTER`` points, chosen
  by a documented, deterministic rule (no randomness, so the same catalogue always shows
  the same points);
* readable bin edges for a range are chosen here (``nice_edges``; the histograms of a
  catalogue's criticality record are then counted in SQL, ``app.dashboard.queries``).

All functions are pure numpy on plain arrays, so they are tested on hand-made data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "GRID_CELLS",
    "MAX_BINS",
    "MAX_SCATTER",
    "histogram",
    "nice_edges",
    "shared_edges",
    "thin_scatter",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: largest number of bars of any histogram sent to the page
MAX_BINS = 60
#: largest number of points of any scatter plot sent to the page
MAX_SCATTER = 2000
#: cells per axis of the envelope grid of ``thin_scatter``
GRID_CELLS = 32


def _finite(values: ArrayLike) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64).ravel()
    return arr[np.isfinite(arr)]


def shared_edges(samples: Sequence[ArrayLike], bins: int = 40,
                 span: tuple[float, float] | None = None,
                 quantiles: tuple[float, float] = (0.0, 1.0)) -> FloatArray:
    """Common bin edges for several samples of one quantity (so overlaid bars align).

    Parameters
    ----------
    samples : sequence of array-like
        Non-finite values are ignored.
    bins : int
        Number of bins, 1 ... ``MAX_BINS``.
    span : (lo, hi), optional
        Fixed range; default: the ``quantiles`` of the pooled finite values (the default
        ``(0, 1)`` is the full range; ``(0.005, 0.995)`` cuts long tails, the values outside
        are then counted as ``below``/``above`` by ``histogram``).

    Returns
    -------
    ndarray of shape (bins + 1,)
        Strictly increasing. A degenerate range (one value, or no finite value) is widened
        to ±0.5 around it (around 0 when there is none).
    """
    if not 1 <= bins <= MAX_BINS:
        raise ValueError(f"bins must be in 1 ... {MAX_BINS}, got {bins}")
    if span is not None:
        lo, hi = float(span[0]), float(span[1])
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"span must be finite with lo < hi, got {span!r}")
    else:
        pooled = np.concatenate([_finite(s) for s in samples]) if samples else np.empty(0)
        if pooled.size == 0:
            lo, hi = -0.5, 0.5
        else:
            q_lo, q_hi = quantiles
            lo, hi = (float(v) for v in np.quantile(pooled, [q_lo, q_hi]))
            if not hi > lo:
                lo, hi = lo - 0.5, hi + 0.5
    return np.linspace(lo, hi, bins + 1)


def histogram(values: ArrayLike, edges: ArrayLike) -> dict[str, Any]:
    """Counts and density of ``values`` on ``edges`` (the last bin includes its right edge).

    Returns
    -------
    dict
        ``edges`` (list, len bins + 1), ``counts`` (list of int), ``density`` (counts / (n
        finite · bin width), so the bars integrate to the share of values inside the
        edges), ``n`` (all values), ``n_finite``, ``below`` and ``above`` (finite values
        outside the edges), ``n_nonfinite``.
    """
    e = np.asarray(edges, dtype=np.float64)
    if e.ndim != 1 or e.size < 2 or not np.all(np.diff(e) > 0):
        raise ValueError("edges must be a strictly increasing 1-d array of >= 2 values")
    arr = np.asarray(values, dtype=np.float64).ravel()
    fin = arr[np.isfinite(arr)]
    counts, _ = np.histogram(fin, bins=e)
    widths = np.diff(e)
    n_fin = int(fin.size)
    density = counts / (n_fin * widths) if n_fin else np.zeros_like(widths)
    return {
        "edges": [float(v) for v in e],
        "counts": [int(c) for c in counts],
        "density": [float(d) for d in density],
        "n": int(arr.size),
        "n_finite": n_fin,
        "below": int((fin < e[0]).sum()),
        "above": int((fin > e[-1]).sum()),
        "n_nonfinite": int(arr.size - n_fin),
    }


def thin_scatter(x: ArrayLike, y: ArrayLike, max_points: int = MAX_SCATTER,
                 cells: int = GRID_CELLS) -> IntArray:
    """Indices of at most ``max_points`` of the finite points (x, y), deterministically.

    The rule (documented in docs/dashboard.md):

    1. Fewer finite points than ``max_points``: all of them.
    2. Otherwise the envelope: the plane spanned by the finite points is cut into
       ``cells`` × ``cells`` equal cells and every occupied cell keeps its point with the
       largest y (ties: the lowest index). Isolated points and the upper edge of the cloud
       — the high-risk scenarios when y is the risk — are therefore always shown. When
       the occupied cells alone exceed ``max_points``, the ones kept are those with the
       largest y (ties: the lowest index).
    3. The remaining budget is filled with points at evenly spaced positions of the
       remaining indices (``floor(k · m / r)``, k = 0 … r − 1, m remaining), so the
       density of the cloud is kept.

    Returns
    -------
    ndarray of int, sorted
        Indices into ``x``/``y``.
    """
    if max_points < 1:
        raise ValueError(f"max_points must be >= 1, got {max_points}")
    xa = np.asarray(x, dtype=np.float64).ravel()
    ya = np.asarray(y, dtype=np.float64).ravel()
    if xa.shape != ya.shape:
        raise ValueError(f"x and y must have the same length, got {xa.size} and {ya.size}")
    ok = np.flatnonzero(np.isfinite(xa) & np.isfinite(ya))
    if ok.size <= max_points:
        return ok.astype(np.int64)
    xs, ys = xa[ok], ya[ok]

    def cell(v: FloatArray) -> IntArray:
        lo, hi = float(v.min()), float(v.max())
        if hi <= lo:
            return np.zeros(v.size, dtype=np.int64)
        c = np.floor((v - lo) / (hi - lo) * cells).astype(np.int64)
        return np.minimum(c, cells - 1)

    key = cell(xs) * cells + cell(ys)
    # sort by cell, then y descending, then index ascending: the first of each cell wins
    order = np.lexsort((ok, -ys, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    envelope = order[first]
    if envelope.size >= max_points:
        by_y = envelope[np.lexsort((ok[envelope], -ys[envelope]))]
        return np.sort(ok[by_y[:max_points]]).astype(np.int64)
    chosen = np.zeros(ok.size, dtype=bool)
    chosen[envelope] = True
    rest = np.flatnonzero(~chosen)
    r = max_points - envelope.size
    picks = rest[(np.arange(r) * rest.size) // r]
    chosen[picks] = True
    return ok[np.flatnonzero(chosen)].astype(np.int64)


#: the bin widths ``nice_edges`` picks from, times a power of ten
NICE_STEPS = (1.0, 2.0, 2.5, 5.0)


def nice_edges(lo: float, hi: float, max_bins: int = 40) -> FloatArray:
    """Bin edges on round numbers covering [lo, hi]: the smallest width of the form
    {1, 2, 2.5, 5} · 10^k that needs at most ``max_bins`` bins, edges at whole multiples of
    it (so 0 … 1.23 with 40 bins gives width 0.05, edges 0, 0.05, …, 1.25).

    A degenerate range (hi - lo at most 1e-6 of the values' magnitude, at least 1) gets
    one bin from ``floor(lo)`` to ``floor(hi) + 1``; lo > hi or a non-finite bound is an
    error.
    """
    if not 1 <= max_bins <= MAX_BINS:
        raise ValueError(f"max_bins must be in 1 ... {MAX_BINS}, got {max_bins}")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"need finite lo <= hi, got {lo!r}, {hi!r}")
    if hi - lo <= 1e-6 * max(1.0, abs(lo), abs(hi)):
        # (nearly) one value: whole-number edges around it, not bins at float resolution
        return np.array([math.floor(lo), math.floor(hi) + 1.0])
    exp = math.floor(math.log10((hi - lo) / max_bins)) - 1
    # a step of 10^top is wider than the range: past it only a range across 0 with
    # max_bins 1 is left (0 is always an edge), which gets plain edges
    top = math.floor(math.log10(hi - lo)) + 1
    while exp <= top:
        for m in NICE_STEPS:
            step = m * 10.0 ** exp
            first, last = math.floor(lo / step), math.ceil(hi / step)
            # lo / step can underflow to -0.0 (a subnormal lo such as -5e-324): keep lo in
            first -= first * step > lo
            last += last * step < hi
            if last == first:
                last += 1
            if last - first <= max_bins:
                # whole multiples of the step, rounded to the step's decimals (no 0.30000000004)
                digits = max(0, 2 - exp)
                return np.round(np.arange(first, last + 1) * step, digits)
        exp += 1
    return np.linspace(lo, hi, max_bins + 1)
