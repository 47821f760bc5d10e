"""sampler.scenario.batch: many vectors' tracks at once equal the builder's, one by one.

The reference is :func:`sampler.scenario.build_scenario` (one concrete scenario per
vector) and riskcore's perception rule on its samples; the batch must match them to 1e-9 m
on the builder's own grid.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets import PARAM_NAMES
from riskcore.criticality import perception_time
from sampler.errors import BuilderError
from sampler.scenario import build_scenario
from sampler.scenario.batch import cutin_tracks, reasons
from tests.sampler.factories import synthetic_parameter_table


def _check_rows(x: np.ndarray, lane_width: float = 3.75) -> int:
    tr = cutin_tracks(x, lane_width=lane_width)
    checked = 0
    for i, row in enumerate(x):
        try:
            sc = build_scenario(dict(zip(PARAM_NAMES, row.tolist(), strict=True)),
                                lane_width=lane_width)
        except BuilderError:
            assert not tr.ok[i], f"row {i}: the builder refuses it, the batch does not"
            continue
        assert tr.ok[i], f"row {i}: {reasons(tr.status[i:i + 1])[0]}"
        c = sc.objects[0]
        m = min(sc.t.shape[0], tr.t.shape[0])
        assert np.array_equal(sc.t[:m], tr.t[:m])
        for mine, ref in ((tr.cx, c.x), (tr.cy, c.y), (tr.cpsi, c.psi), (tr.cv, c.v),
                          (tr.ca, c.a), (tr.c_yaw_rate, c.yaw_rate)):
            assert ref is not None
            assert np.max(np.abs(mine[i, :m] - ref[:m])) <= 1e-9
        assert sc.ego.v is not None
        assert tr.ego_v0[i] == pytest.approx(sc.ego.v[0], abs=1e-12)
        assert tr.t_cross[i] == pytest.approx(sc.provenance["t_cross"], abs=1e-12)
        tp = perception_time(sc, c)
        assert tp is not None and tr.t_p[i] == pytest.approx(tp, abs=1e-9)
        checked += 1
    return checked


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_equal_to_the_builder_on_many_vectors() -> None:
    table = synthetic_parameter_table(120, seed=5)
    x = table[list(PARAM_NAMES)].to_numpy(dtype=np.float64).copy()
    # pulses starting before, during and after the lane change; a pulse edge on the grid
    x[:10, 3] = np.linspace(-2.0, 6.0, 10)
    x[10, 3], x[10, 4] = 1.0, 0.5
    assert _check_rows(x) >= 110


@settings(max_examples=40, deadline=None)
@given(p_y1=st.floats(0.02, 0.12), side=st.sampled_from([-1.0, 1.0]),
       p_t=st.floats(1.0, 5.0), p_a1=st.floats(-3.0, 3.0), p_a2=st.floats(-3.0, 6.0),
       p_a3=st.floats(0.0, 4.0), p_v0=st.floats(10.0, 35.0), dv=st.floats(-5.0, 8.0),
       gap=st.floats(0.5, 60.0), lane_width=st.floats(3.0, 4.0))
def test_equal_to_the_builder_property(p_y1: float, side: float, p_t: float, p_a1: float,
                                       p_a2: float, p_a3: float, p_v0: float, dv: float,
                                       gap: float, lane_width: float) -> None:
    x = np.array([[side * p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap]])
    _check_rows(x, lane_width)


def test_refused_rows_are_reported_not_raised() -> None:
    x = np.array([[0.05, 2.5, 0.0, 0.0, 0.0, 25.0, 2.0, 12.0],
                  [0.0, 2.5, 0.0, 0.0, 0.0, 25.0, 2.0, 12.0],      # no yaw
                  [0.001, 2.5, 0.0, 0.0, 0.0, 25.0, 2.0, 12.0],    # never crosses
                  [0.05, 2.5, 0.0, 0.0, 0.0, 25.0, -40.0, 12.0],   # ego speed < 0
                  [0.05, 2.5, -5.0, 0.0, 8.0, 25.0, 2.0, 12.0]])   # cutter reverses
    tr = cutin_tracks(x)
    assert tr.ok.tolist() == [True, False, False, False, False]
    why = reasons(tr.status)
    assert why[0] is None and "p_y1" in str(why[1]) and "marking" in str(why[2])
    assert "ego speed" in str(why[3]) and "negative" in str(why[4])


def test_the_grid_holds_every_script_and_the_cutter_goes_on_straight() -> None:
    x = np.array([[0.05, 2.5, 1.0, 1.0, 2.0, 25.0, 2.0, 12.0],
                  [0.05, 4.0, 0.0, 0.0, 0.0, 25.0, 2.0, 12.0]])
    tr = cutin_tracks(x)
    # the longest script ends at 2.5 + 8 s; plus the 3 s horizon
    assert tr.t[-1] == pytest.approx(13.5)
    assert tr.t_end.tolist() == pytest.approx([2.5 + 5.0, 2.5 + 8.0])
    after = tr.t > tr.t_end[0] + 1e-9
    v = tr.cv[0, after]
    assert np.all(v == v[0]) and np.all(tr.cpsi[0, after] == 0.0)
    dx = np.diff(tr.cx[0, after])
    assert np.allclose(dx, v[0] * 0.1, rtol=0, atol=1e-9)


def test_cutin_batch_equals_the_batch_of_built_scenarios() -> None:
    from riskcore.sut import CutInBatch
    from sampler.scenario import cutin_batch

    table = synthetic_parameter_table(40, seed=9)
    x = table[list(PARAM_NAMES)].to_numpy(dtype=np.float64)
    x = x[cutin_tracks(x).ok]
    mine = cutin_batch(x)
    ref = CutInBatch.from_scenarios(
        [build_scenario(dict(zip(PARAM_NAMES, r.tolist(), strict=True))) for r in x])
    m = min(mine.t.shape[0], ref.t.shape[0])
    for name in ("cx", "cy", "cpsi", "cv", "ca", "c_yaw_rate"):
        assert np.max(np.abs(getattr(mine, name)[:, :m] - getattr(ref, name)[:, :m])) <= 1e-9
    for name in ("ego_v0", "t_p", "t_cross", "c_length", "c_width"):
        assert np.allclose(getattr(mine, name), getattr(ref, name), rtol=0, atol=1e-9), name
    with pytest.raises(BuilderError, match=r"params\[1\]"):
        cutin_batch(np.array([x[0], [0.0, 2.5, 0, 0, 0, 25.0, 2.0, 12.0]]))


def test_buildable_batch_equals_cutin_batch_of_the_buildable_rows() -> None:
    """One build for ``ok`` and the batch: array for array ``cutin_batch(x[rows])``, also
    when a refused row has the longest script (its grid is then cut to the buildable
    rows' one) and with an explicit duration."""
    from sampler.scenario.batch import buildable_batch, cutin_batch

    x = synthetic_parameter_table(60, seed=8)[list(PARAM_NAMES)].to_numpy(
        dtype=np.float64).copy()
    x[3, 0] = 0.0  # no lane change
    x[4, 1], x[4, 0] = 30.0, 1e-4  # the longest script, never reaches the marking
    x[5, 2] = np.nan
    for duration in (None, 20.0):
        status, rows, batch = buildable_batch(x, lane_width=3.5, ego_length=4.2,
                                              ego_width=1.7, cutter_length=5.0,
                                              cutter_width=2.0, duration=duration)
        ref_tr = cutin_tracks(x, lane_width=3.5, ego_length=4.2, cutter_length=5.0,
                              duration=duration)
        assert np.array_equal(status, ref_tr.status)
        assert rows.tolist() == np.flatnonzero(ref_tr.ok).tolist()
        assert {3, 4, 5}.isdisjoint(rows.tolist()) and rows.size >= 40
        ref = cutin_batch(x[rows], lane_width=3.5, ego_length=4.2, ego_width=1.7,
                          cutter_length=5.0, cutter_width=2.0, duration=duration)
        assert batch is not None
        if duration is None:  # the refused row 4 made the tracks' grid longer
            assert ref_tr.t.shape[0] > ref.t.shape[0] + 100
        for name in ("t", "ego_v0", "cx", "cy", "cpsi", "cv", "ca", "c_length", "c_width",
                     "t_p", "t_cross", "t_end", "c_yaw_rate"):
            a, b = getattr(batch, name), getattr(ref, name)
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), name
            assert a.flags.c_contiguous, name
        for name in ("lane_width", "ego_length", "ego_width"):
            assert getattr(batch, name) == getattr(ref, name)
    none = buildable_batch(x[3:6])
    assert none[1].size == 0 and none[2] is None


def test_own_grid_steps_by_hand() -> None:
    """A row's own grid: lead-in 2.5 s + max(2 p_t, pulse end) + 3 s, in steps of 0.1 s,
    rounded up to a whole 5 s; a refused row (not finite) gets the first bin."""
    from sampler.scenario.batch import own_grid_steps

    x = np.array([[0.1, 2.0, 0.0, 0.0, 1.0, 25.0, 1.0, 10.0],  # 2.5 + 4 + 3 = 9.5 s -> 10
                  [0.1, 12.0, 0.0, 0.0, 1.0, 25.0, 1.0, 10.0],  # 2.5 + 24 + 3 -> 30 s
                  [0.1, 1.0, -1.0, 3.0, 6.0, 25.0, 1.0, 10.0],  # pulse ends at 9: 14.5 -> 15
                  [0.1, 2.25, 0.0, 0.0, 0.0, 25.0, 1.0, 10.0],  # exactly 10 s -> 10
                  [0.1, np.nan, 0.0, 0.0, 0.0, 25.0, 1.0, 10.0]])  # 5.5 s -> 10
    assert own_grid_steps(x).tolist() == [100, 300, 150, 100, 100]
    assert own_grid_steps(x, dt=0.05, lead_in=0.0).tolist() == [200, 600, 300, 200, 100]


def test_buildable_batches_put_each_row_on_its_own_grid() -> None:
    """Every batch equals ``cutin_batch`` of its rows on their own grid, array for array;
    the rows of all batches are the buildable ones, each once."""
    from sampler.scenario.batch import buildable_batches, cutin_batch, own_grid_steps

    x = synthetic_parameter_table(80, seed=9)[list(PARAM_NAMES)].to_numpy(
        dtype=np.float64).copy()
    x[3, 0] = 0.0  # no lane change
    x[4, 1], x[4, 0] = 30.0, 1e-4  # the longest script, never reaches the marking
    x[5, 2] = np.nan
    x[6, 1] = 12.0  # a long lane change: a grid of its own
    status, groups = buildable_batches(x, lane_width=3.5, ego_length=4.2, ego_width=1.7,
                                       cutter_length=5.0, cutter_width=2.0)
    ref_tr = cutin_tracks(x, lane_width=3.5, ego_length=4.2, cutter_length=5.0)
    assert np.array_equal(status, ref_tr.status)
    rows = np.concatenate([r for r, _ in groups])
    assert sorted(rows.tolist()) == np.flatnonzero(ref_tr.ok).tolist()
    assert len(groups) >= 2 and 6 in rows
    steps = own_grid_steps(x)
    for r, batch in groups:
        assert (steps[r] == steps[r[0]]).all()
        assert batch.t.shape[0] == steps[r[0]] + 1
        ref = cutin_batch(x[r], lane_width=3.5, ego_length=4.2, ego_width=1.7,
                          cutter_length=5.0, cutter_width=2.0,
                          duration=float(steps[r[0]]) * 0.1)
        for name in ("t", "ego_v0", "cx", "cy", "cpsi", "cv", "ca", "c_length", "c_width",
                     "t_p", "t_cross", "t_end", "c_yaw_rate"):
            a, b = getattr(batch, name), getattr(ref, name)
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), name


def _quad_tracks(row: np.ndarray, t: np.ndarray, lane_width: float = 3.75,
                 lead_in: float = 2.5, length: float = 4.5) -> tuple[np.ndarray, np.ndarray,
                                                                     float]:
    """The cutter's centre (cx, cy) and t_cross by the builder's definitions, the integrals
    by scipy's adaptive quadrature (pulse edges as break points, 1e-13) and the crossing
    by brentq: a reference independent of the builder's rule."""
    import math

    from scipy.integrate import quad
    from scipy.optimize import brentq

    p_y1, p_t, a1, a2, a3, v0, dv, gap = (float(v) for v in row)
    amp = p_y1 * p_t / math.pi
    end = 2.0 * p_t

    def v(s: float) -> float:
        return v0 + a1 * (min(max(s - a2, 0.0), a3) - min(max(-a2, 0.0), a3))

    def integral(trig: object, a: float, b: float) -> float:
        pts = [k for k in (a2, a2 + a3) if a < k < b]
        return float(quad(lambda s: v(s) * trig(amp * (1.0 - math.cos(math.pi * s / p_t))),  # type: ignore[operator]
                          a, b, points=pts or None, epsabs=1e-13, epsrel=1e-13,
                          limit=200)[0])

    def straight(s: float) -> float:  # int_0^s v, exact
        u = min(max(s - a2, 0.0), a3)
        u0 = min(max(-a2, 0.0), a3)
        return v0 * s + a1 * (0.5 * u * u + a3 * max(s - a2 - a3, 0.0)
                              - 0.5 * u0 * u0 - a3 * max(-a2 - a3, 0.0) - u0 * s)

    tc = brentq(lambda s: abs(integral(math.sin, 0.0, s)) - lane_width / 2.0, 0.0, end,
                xtol=1e-15, rtol=1e-15)
    xe, ye = integral(math.cos, 0.0, end), integral(math.sin, 0.0, end)
    x0 = gap + length + (v(tc) + dv) * (lead_in + tc) - integral(math.cos, 0.0, tc)
    cx, cy = np.empty(t.size), np.empty(t.size)
    for k, tk in enumerate(t - lead_in):
        if tk <= 0.0:
            xr, yr = straight(tk), 0.0
        elif tk > end:
            xr, yr = xe + straight(tk) - straight(end), ye
        else:
            xr, yr = integral(math.cos, 0.0, tk), integral(math.sin, 0.0, tk)
        cx[k] = x0 + xr
        cy[k] = (-lane_width if p_y1 > 0 else lane_width) + yr
    return cx, cy, lead_in + tc


def test_tracks_equal_adaptive_quadrature_and_beat_the_previous_rule() -> None:
    """Model-like vectors: the tracks (centre, crossing moment) against QUADPACK within
    1e-9 m and 1e-10 s; the previous rule (1 ms trapezoid) is off by more (~1e-6 m)."""
    x = synthetic_parameter_table(40, seed=12)[list(PARAM_NAMES)].to_numpy(dtype=np.float64)
    new = cutin_tracks(x)
    old = cutin_tracks(x, quadrature="trapezoid")
    rows = np.flatnonzero(new.ok)[:12]
    assert rows.size >= 8 and old.ok[rows].all()
    err_new = err_old = 0.0
    for i in rows:
        cx, cy, tc = _quad_tracks(x[i], new.t)
        e = max(np.abs(new.cx[i] - cx).max(), np.abs(new.cy[i] - cy).max())
        assert e < 1e-9 and abs(new.t_cross[i] - tc) < 1e-10, i
        err_new = max(err_new, e)
        err_old = max(err_old, np.abs(old.cx[i] - cx).max(), np.abs(old.cy[i] - cy).max())
    assert err_old > 100 * err_new and err_old > 1e-8


def test_unknown_quadrature_is_refused() -> None:
    with pytest.raises(BuilderError, match="quadrature"):
        cutin_tracks(np.zeros((1, 8)), quadrature="simpson")
