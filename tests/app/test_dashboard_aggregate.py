"""The dashboard's server-side aggregation on hand-made data (app.dashboard.aggregate,
app.domain.marginal_density, app.dashboard.views.split_constraints)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from app import domain
from app.dashboard.aggregate import histogram, nice_edges, shared_edges, thin_scatter
from app.dashboard.views import split_constraints
from app.errors import InvalidInput
from sampler.model.gmm import CutInGMM


# --------------------------------------------------------------------------- histogram
def test_histogram_counts_density_and_overflow_by_hand() -> None:
    values = [0.0, 0.5, 1.0, 1.5, 2.0, math.inf, math.nan, 5.0, -1.0]
    h = histogram(values, [0.0, 1.0, 2.0])
    # [0, 1): 0, 0.5   [1, 2]: 1, 1.5, 2 (last bin closed); 5 above, -1 below
    assert h["counts"] == [2, 3]
    assert h["n"] == 9 and h["n_finite"] == 7 and h["n_nonfinite"] == 2
    assert h["below"] == 1 and h["above"] == 1
    assert h["density"] == pytest.approx([2 / 7, 3 / 7])
    assert h["edges"] == [0.0, 1.0, 2.0]


def test_histogram_of_nothing_is_zero_not_nan() -> None:
    h = histogram([], [0.0, 0.5, 1.0])
    assert h["counts"] == [0, 0] and h["density"] == [0.0, 0.0] and h["n"] == 0


def test_histogram_rejects_bad_edges() -> None:
    with pytest.raises(ValueError, match="strictly increasing"):
        histogram([1.0], [1.0, 1.0])


def test_shared_edges_cover_all_samples_or_the_given_span() -> None:
    assert list(shared_edges([[1.0, 3.0], [2.0, 5.0, math.inf]], bins=4)) == \
        [1.0, 2.0, 3.0, 4.0, 5.0]
    assert list(shared_edges([], bins=2, span=(0.0, 1.0))) == [0.0, 0.5, 1.0]
    assert list(shared_edges([[2.0, 2.0]], bins=2)) == [1.5, 2.0, 2.5]
    assert list(shared_edges([[]], bins=1)) == [-0.5, 0.5]
    with pytest.raises(ValueError, match="bins"):
        shared_edges([[1.0]], bins=61)
    with pytest.raises(ValueError, match="span"):
        shared_edges([[1.0]], bins=3, span=(1.0, 1.0))


def test_shared_edges_quantiles_cut_the_tails() -> None:
    values = np.concatenate([np.arange(100.0), [1e6]])
    edges = shared_edges([values], bins=10, quantiles=(0.0, 0.99))
    # 101 values: the 0.99 quantile sits at position 0.99 * 100 = 99, the value 99
    assert edges[-1] == pytest.approx(99.0)
    assert histogram(values, edges)["above"] == 1


# --------------------------------------------------------------------------- scatter
def test_thin_scatter_keeps_every_finite_point_under_the_budget() -> None:
    x = [0.0, 1.0, math.inf, 3.0, 4.0]
    y = [1.0, math.nan, 2.0, 3.0, 4.0]
    assert thin_scatter(x, y, max_points=10).tolist() == [0, 3, 4]


def test_thin_scatter_bounds_the_points_and_keeps_outliers_and_the_top() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 1.0, 10_000)
    y = rng.uniform(0.0, 0.5, 10_000)
    x[1234], y[1234] = 40.0, 0.1  # an isolated point far right
    y[777] = 0.99  # the highest y
    keep = thin_scatter(x, y, max_points=500, cells=16)
    assert keep.size == 500
    assert 1234 in keep and 777 in keep
    assert np.all(np.diff(keep) > 0)
    assert thin_scatter(x, y, max_points=500, cells=16).tolist() == keep.tolist()


def test_thin_scatter_with_more_cells_than_budget_keeps_the_highest() -> None:
    x = np.arange(100.0)
    y = np.arange(100.0) / 100.0
    keep = thin_scatter(x, y, max_points=5, cells=50)
    # on the diagonal each cell (width 99/50) holds two neighbours, e.g. {98, 99}, {96, 97},
    # {94, 95}, {92, 93}, {90, 91}: each keeps its upper one; the five highest of those
    assert keep.tolist() == [91, 93, 95, 97, 99]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True, width=32),
                          st.floats(allow_nan=True, allow_infinity=True, width=32)),
                max_size=300),
       st.integers(min_value=1, max_value=50))
def test_thin_scatter_properties(points: list[tuple[float, float]], budget: int) -> None:
    x = np.array([p[0] for p in points], dtype=np.float64)
    y = np.array([p[1] for p in points], dtype=np.float64)
    keep = thin_scatter(x, y, max_points=budget, cells=8)
    finite = int((np.isfinite(x) & np.isfinite(y)).sum())
    assert keep.size == min(budget, finite)
    assert len(set(keep.tolist())) == keep.size
    assert np.all(np.isfinite(x[keep])) and np.all(np.isfinite(y[keep]))


# --------------------------------------------------------------------------- nice edges
@pytest.mark.parametrize("lo, hi, bins, expected", [
    (0.0, 1.23, 40, [0.05 * k for k in range(26)]),       # width 0.05: 0 … 1.25
    (0.0, 1.0, 20, [0.05 * k for k in range(21)]),
    (0.0, 7.0, 40, [0.2 * k for k in range(36)]),          # 0.1 would need 70 bins
    (0.0, 10.0, 4, [0.0, 2.5, 5.0, 7.5, 10.0]),
    (-3.0, 3.0, 3, [-5.0, 0.0, 5.0]),                      # edges at multiples of the width
    (2.0, 2.0, 40, [2.0, 3.0]),                            # degenerate: one bin of 1
    (128.0, 128.00000001, 40, [128.0, 129.0]),             # nearly: no float-resolution bins
    (0.99999999, 1.00000001, 40, [0.0, 2.0]),
    (-1.0, 1.0, 1, [-1.0, 1.0]),                            # across 0 in one bin
])
def test_nice_edges_by_hand(lo: float, hi: float, bins: int, expected: list[float]) -> None:
    assert nice_edges(lo, hi, bins).tolist() == pytest.approx(expected, abs=1e-12)


def test_nice_edges_have_no_float_noise() -> None:
    edges = nice_edges(0.0, 1.0, 40)  # width 0.025
    assert [repr(float(e)) for e in edges[:5]] == ["0.0", "0.025", "0.05", "0.075", "0.1"]


@given(st.floats(-1e6, 1e6), st.floats(0.0, 1e6), st.integers(1, 60))
@settings(max_examples=200, deadline=None)
def test_nice_edges_cover_the_range_with_at_most_max_bins(lo: float, width: float,
                                                          bins: int) -> None:
    hi = lo + width
    e = nice_edges(lo, hi, bins)
    assert 2 <= e.size <= bins + 1
    assert e[0] <= lo and e[-1] >= hi
    assert np.all(np.diff(e) > 0)
    assert np.allclose(np.diff(e), e[1] - e[0], rtol=1e-6, atol=0)


def test_nice_edges_cover_a_subnormal_lower_end() -> None:
    """Found by the property above: with lo = -5e-324 and a step of 100, lo / step
    underflows to -0.0 and the first edge was 0.0 > lo; now it is one step below 0."""
    e = nice_edges(-5e-324, 1000.0, 10)
    assert e[0] <= -5e-324 and e[-1] >= 1000.0
    # the 100 step would need 11 bins with the extra one below 0: 200, edges -200 ... 1000
    assert e[0] == -200.0 and e.size == 7


def test_nice_edges_refuse_bad_input() -> None:
    with pytest.raises(ValueError):
        nice_edges(1.0, 0.0)
    with pytest.raises(ValueError):
        nice_edges(0.0, math.inf)
    with pytest.raises(ValueError):
        nice_edges(0.0, 1.0, 0)


def test_split_constraints() -> None:
    assert split_constraints(" ttc<3; v_ego>=20 ,gap>1 & dv>0;; ") == \
        ["ttc<3", "v_ego>=20", "gap>1", "dv>0"]
    assert split_constraints("   ") == []


# --------------------------------------------------------------------------- marginal
def _two_component_model() -> CutInGMM:
    """A hand-made mixture over (dv, gap): dv identity (loc 1, scale 2), gap log (loc 3,
    scale 0.5); the other parameters fixed."""
    return CutInGMM.from_dict({
        "format": "scengen.cutin-gmm/1",
        "features": ["dv", "gap"],
        "transforms": [
            {"feature": "dv", "kind": "identity", "shift": 0.0, "loc": 1.0, "scale": 2.0},
            {"feature": "gap", "kind": "log", "shift": 0.0, "loc": 3.0, "scale": 0.5},
        ],
        "fixed": {"p_y1": 0.04, "p_t": 2.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
                  "p_v0": 25.0},
        "weights": [0.3, 0.7],
        "means": [[-1.0, 0.5], [1.0, -0.5]],
        "covariances": [[[0.25, 0.1], [0.1, 1.0]], [[1.0, -0.3], [-0.3, 0.64]]],
    })


def test_marginal_density_is_the_mixture_of_the_component_marginals() -> None:
    model = _two_component_model()
    dv = np.array([-3.0, 0.0, 1.0, 2.5])
    z = (dv - 1.0) / 2.0
    want_dv = (0.3 * stats.norm.pdf(z, -1.0, 0.5) + 0.7 * stats.norm.pdf(z, 1.0, 1.0)) / 2.0
    assert domain.marginal_density(model, "dv", dv) == pytest.approx(want_dv, rel=1e-12)
    gap = np.array([5.0, 20.0, 40.0])
    zg = (np.log(gap) - 3.0) / 0.5
    want_gap = (0.3 * stats.norm.pdf(zg, 0.5, 1.0) + 0.7 * stats.norm.pdf(zg, -0.5, 0.8)) \
        / (0.5 * gap)
    assert domain.marginal_density(model, "gap", gap) == pytest.approx(want_gap, rel=1e-12)
    # outside the log transform's domain: density 0
    assert domain.marginal_density(model, "gap", np.array([-1.0, 0.0])).tolist() == [0.0, 0.0]


def test_marginal_density_integrates_to_one_and_matches_the_joint() -> None:
    model = _two_component_model()
    grid = np.linspace(-15.0, 17.0, 4001)
    assert np.trapezoid(domain.marginal_density(model, "dv", grid), grid) == \
        pytest.approx(1.0, abs=1e-6)
    # numerical integral of the joint density over gap at dv = 0.5
    gaps = np.exp(np.linspace(np.log(0.05), np.log(5000.0), 20001))
    joint = np.exp(model.log_density(np.column_stack([np.full_like(gaps, 0.5), gaps])))
    assert np.trapezoid(joint, gaps) == pytest.approx(
        float(domain.marginal_density(model, "dv", np.array([0.5]))[0]), rel=1e-4)


def test_marginal_density_of_a_fixed_parameter_is_an_error() -> None:
    with pytest.raises(InvalidInput, match="not a feature"):
        domain.marginal_density(_two_component_model(), "p_v0", np.array([1.0]))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=200),
       st.floats(min_value=-1e3, max_value=1e3), st.floats(min_value=1e-3, max_value=1e3),
       st.integers(min_value=1, max_value=60))
def test_histogram_accounts_for_every_value(values: list[float], lo: float, width: float,
                                            bins: int) -> None:
    h = histogram(values, shared_edges([], bins=bins, span=(lo, lo + width)))
    assert sum(h["counts"]) + h["below"] + h["above"] == h["n_finite"]
    assert h["n_finite"] + h["n_nonfinite"] == len(values)
    assert len(h["counts"]) == bins


# --------------------------------------------------------------------------- diagnostics
def test_sampler_diagnostics_over_chunks_by_hand() -> None:
    from types import SimpleNamespace

    from app.dashboard.views import _diagnostics

    chunks = [
        SimpleNamespace(diagnostics={"sampler": {
            "method": "mcmc", "acceptance_mean": 0.3, "acceptance_min": 0.2, "tau_max": 12.0,
            "ess": 40.0, "warnings": ["chain shorter than 50 tau"]}}),
        SimpleNamespace(diagnostics={"sampler": {
            "method": "mcmc", "acceptance_mean": 0.5, "acceptance_min": 0.1, "tau_max": 30.0,
            "ess": 25.0, "warnings": []}}),
        SimpleNamespace(diagnostics={"sampler": {
            "method": "rejection", "acceptance_rate": 0.05, "ess": 50.0, "n_draws": 500}}),
    ]
    d = _diagnostics(chunks)
    assert d.chunks == 3 and d.methods == ["mcmc", "rejection"]
    assert d.acceptance_mean == pytest.approx((0.05 + 0.3 + 0.5) / 3)
    assert d.acceptance_min == pytest.approx(0.05)  # the rejection chunk's rate
    assert d.tau_max == 30.0 and d.ess_total == 115.0 and d.n_draws == 500.0
    assert d.warnings == ["chain shorter than 50 tau"]
    empty = _diagnostics([])
    assert empty.chunks == 0 and empty.acceptance_mean is None


# --------------------------------------------------------------------------- cache
def test_view_cache_computes_a_key_once_even_concurrently_and_evicts_lru(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import threading

    from app.dashboard.views import ViewCache

    cache = ViewCache(size=2)
    # Release the first computation only after the second caller has missed the cache:
    # from then on a cache without per-key waiting would compute a second time.
    second_missed = threading.Event()
    second: threading.Thread | None = None  # set below; the spy reads it when called
    lookup = cache._lookup

    def spying_lookup(key: tuple[Any, ...]) -> tuple[bool, Any]:
        found, value = lookup(key)
        if threading.current_thread() is second and not found:
            second_missed.set()
        return found, value

    monkeypatch.setattr(cache, "_lookup", spying_lookup)
    calls: list[str] = []
    started, release = threading.Event(), threading.Event()

    def slow() -> str:
        calls.append("slow")
        started.set()
        assert release.wait(timeout=60)
        return "value"

    results: list[str] = []
    first = threading.Thread(target=lambda: results.append(cache.get(("k",), slow)))
    first.start()
    assert started.wait(timeout=60)
    second = threading.Thread(target=lambda: results.append(cache.get(("k",), slow)))
    second.start()
    assert second_missed.wait(timeout=60)
    release.set()
    first.join(timeout=60)
    second.join(timeout=60)
    assert results == ["value", "value"] and calls == ["slow"]
    # least recently used goes first
    cache.get(("a",), lambda: "A")
    cache.get(("k",), lambda: "recomputed")  # touch k
    cache.get(("b",), lambda: "B")  # evicts a
    assert cache.get(("k",), lambda: "recomputed") == "value"
    assert cache.get(("a",), lambda: "A again") == "A again"
    # a failing computation is not cached
    with pytest.raises(RuntimeError):
        cache.get(("bad",), lambda: (_ for _ in ()).throw(RuntimeError("boom")))
    assert cache.get(("bad",), lambda: "ok") == "ok"


def test_shift_bins_hold_both_samples() -> None:
    """Issue 14 item 9: a small constrained sample far in the tail of the unconstrained one
    is binned inside the range, not piled up outside its edges (hand-made samples)."""
    import pandas as pd

    from app.dashboard.views import _shift, bins_for_both

    rng = np.random.default_rng(3)
    ref = rng.normal(0.0, 1.0, 10_000)
    con = rng.normal(8.0, 0.1, 100)  # 1 % of the pooled values, all beyond ref's 99.5 %
    edges = bins_for_both([ref, con], bins=40)
    assert edges[0] <= np.quantile(ref, 0.005) and edges[-1] >= np.quantile(con, 0.995)
    views = _shift(pd.DataFrame({n: ref for n in domain.PARAM_NAMES}),
                   pd.DataFrame({n: con for n in domain.PARAM_NAMES}))
    for view in views:
        hist = view.constrained
        assert hist.below + hist.above <= 2, view.name  # only the 0.5 % tails
        assert sum(hist.counts) >= 98
