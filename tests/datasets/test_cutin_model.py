"""Cut-in kinematics against hand-computed values and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets.cutin_model import (
    PARAM_NAMES,
    CutInParamError,
    CutInParams,
    crossing_time,
    heading,
    lateral_displacement,
    motion,
    speed,
    ttc_from_gap_dv,
)


def _params(**kw: float) -> CutInParams:
    base = dict(p_y1=0.05, p_t=2.0, p_a1=0.0, p_a2=0.0, p_a3=0.0, p_v0=20.0, dv=1.0, gap=10.0)
    base.update(kw)
    return CutInParams.from_mapping(base)


def test_heading_peaks_at_p_t_and_returns_to_zero() -> None:
    p = _params(p_y1=0.05, p_t=2.0)
    # psi(p_t) = 2 p_y1 p_t / pi, by hand: 2 * 0.05 * 2 / pi = 0.063662
    assert heading(p, 2.0) == pytest.approx(0.2 / math.pi, rel=1e-12)
    assert heading(p, 4.0) == pytest.approx(0.0, abs=1e-15)
    assert heading(p, -1.0) == 0.0 and heading(p, 5.0) == 0.0


def test_speed_pulse_by_hand() -> None:
    # pulse of -2 m/s^2 from t = 1 s for 1.5 s: v(3) = 20 - 3 = 17
    p = _params(p_a1=-2.0, p_a2=1.0, p_a3=1.5)
    assert speed(p, [0.0, 1.0, 2.0, 2.5, 3.0]) == pytest.approx([20, 20, 18, 17, 17])
    # pulse starting before t = 0 keeps v(0) = p_v0
    q = _params(p_a1=1.0, p_a2=-1.0, p_a3=2.0)
    assert speed(q, [-2.0, 0.0, 1.0, 2.0]) == pytest.approx([19.0, 20.0, 21.0, 21.0])


def test_straight_motion_is_exact() -> None:
    p = _params(p_y1=0.0, p_a1=1.0, p_a2=0.0, p_a3=2.0)
    m = motion(p, [0.0, 1.0, 2.0, 3.0])
    # x = v0 t + a t^2 / 2 during the pulse, then constant speed 22 m/s
    assert m.x == pytest.approx([0.0, 20.5, 42.0, 64.0], abs=1e-9)
    assert m.y == pytest.approx([0.0] * 4, abs=1e-12)


def test_lateral_displacement_small_angle_closed_form() -> None:
    # constant v: y(2 p_t) = int v sin(psi) ~ v * int psi = v * p_y1 p_t / pi * 2 p_t
    p = _params(p_y1=0.01, p_t=2.0, p_v0=20.0)
    small_angle = 20.0 * 0.01 * 2.0 / math.pi * 4.0
    assert lateral_displacement(p) == pytest.approx(small_angle, rel=2e-4)


@settings(max_examples=40, deadline=None)
@given(p_y1=st.floats(0.01, 0.15), p_t=st.floats(1.0, 4.0), v0=st.floats(10.0, 40.0))
def test_crossing_is_near_p_t_for_a_symmetric_lane_change(p_y1: float, p_t: float,
                                                          v0: float) -> None:
    p = _params(p_y1=p_y1, p_t=p_t, p_v0=v0)
    half = lateral_displacement(p) / 2.0
    # constant speed: the motion is point-symmetric about t = p_t
    assert crossing_time(p, half) == pytest.approx(p_t, abs=2e-3)


def test_crossing_left_and_right_are_mirror_images() -> None:
    left, right = _params(p_y1=0.06), _params(p_y1=-0.06)
    assert crossing_time(left, 1.0) == pytest.approx(crossing_time(right, 1.0), abs=1e-12)
    assert motion(left, [3.0]).y[0] == pytest.approx(-motion(right, [3.0]).y[0], abs=1e-12)


def test_no_crossing_is_a_clear_error() -> None:
    with pytest.raises(CutInParamError, match="never reaches"):
        crossing_time(_params(p_y1=0.001), 1.875)


def test_validation_names_the_parameter() -> None:
    with pytest.raises(CutInParamError, match="p_t"):
        _params(p_t=0.0)
    with pytest.raises(CutInParamError, match="p_a3"):
        _params(p_a3=-0.1)
    with pytest.raises(CutInParamError, match="missing parameter"):
        CutInParams.from_mapping({"p_y1": 0.1})
    assert tuple(_params().as_dict()) == PARAM_NAMES


def test_ttc() -> None:
    assert ttc_from_gap_dv([10.0, 10.0, 10.0], [2.0, 0.0, -1.0]) == pytest.approx(
        [5.0, np.inf, np.inf])


def _motion_reference(p: CutInParams, t: np.ndarray, substep: float = 1e-3
                      ) -> tuple[np.ndarray, np.ndarray]:
    """x(t), y(t) the straightforward way: sort the whole integration grid, evaluate the
    heading, cos and sin at every grid point (what ``motion`` did before it skipped the
    trigonometry where the cutter does not turn)."""
    lo, hi = min(float(t.min()), 0.0), max(float(t.max()), 0.0)
    n_sub = max(int(np.ceil((hi - lo) / substep)), 1)
    edges = [p.p_a2, p.p_a2 + p.p_a3, 0.0, 2.0 * p.p_t]
    grid = np.unique(np.concatenate([np.linspace(lo, hi, n_sub + 1),
                                     [e for e in edges if lo < e < hi]]))
    v, psi = speed(p, grid), heading(p, grid)
    dx = 0.5 * (v[1:] * np.cos(psi[1:]) + v[:-1] * np.cos(psi[:-1])) * np.diff(grid)
    dy = 0.5 * (v[1:] * np.sin(psi[1:]) + v[:-1] * np.sin(psi[:-1])) * np.diff(grid)
    xg, yg = np.concatenate([[0.0], np.cumsum(dx)]), np.concatenate([[0.0], np.cumsum(dy)])
    i0 = int(np.searchsorted(grid, 0.0))
    return np.interp(t, grid, xg - xg[i0]), np.interp(t, grid, yg - yg[i0])


@settings(max_examples=40, deadline=None)
@given(p_y1=st.floats(-0.1, 0.1).filter(lambda v: v != 0), p_t=st.floats(0.5, 5.0),
       p_a1=st.floats(-2.0, 2.0), p_a2=st.floats(-3.0, 6.0), p_a3=st.floats(0.0, 4.0),
       lead=st.floats(0.0, 4.0), span=st.floats(0.0, 15.0), n=st.integers(1, 300))
def test_motion_equals_the_straightforward_integration(p_y1: float, p_t: float, p_a1: float,
                                                       p_a2: float, p_a3: float, lead: float,
                                                       span: float, n: int) -> None:
    p = CutInParams(p_y1=p_y1, p_t=p_t, p_a1=p_a1, p_a2=p_a2, p_a3=p_a3, p_v0=25.0, dv=1.0,
                    gap=10.0)
    t = np.linspace(-lead, span, n)
    m = motion(p, t)
    x_ref, y_ref = _motion_reference(p, t)
    # both are the trapezoid rule on 1 ms steps (motion only during the lane change, the
    # straight parts exact): they agree to the rule's error, O(substep^2)
    np.testing.assert_allclose(m.x, x_ref, rtol=0, atol=2e-6)
    np.testing.assert_allclose(m.y, y_ref, rtol=0, atol=2e-6)
    np.testing.assert_array_equal(m.psi, heading(p, t))


def test_straight_parts_are_exact_by_hand() -> None:
    """Before the lane change and after it the heading is 0: x is the integral of the
    piecewise linear speed, in closed form (a pulse of 1 m/s^2 from t = -1 s for 2 s)."""
    p = CutInParams(p_y1=0.05, p_t=2.0, p_a1=1.0, p_a2=-1.0, p_a3=2.0, p_v0=20.0, dv=1.0,
                    gap=10.0)
    # v(t) = 20 + (t + 1) - 1 = 20 + t on [-1, 1]; 19 before -1; 21 after 1
    m = motion(p, [-3.0, -1.0, -0.5])
    assert m.x[0] == pytest.approx(-(0.5 * (19 + 20) * 1.0 + 19 * 2.0), abs=1e-12)
    assert m.x[1] == pytest.approx(-0.5 * (19 + 20) * 1.0, abs=1e-12)
    assert m.x[2] == pytest.approx(-0.5 * (19.5 + 20) * 0.5, abs=1e-12)
    assert (m.y == 0.0).all()
    end = motion(p, [4.0, 6.0])  # the lane change ends at 2 p_t = 4 s; then 21 m/s straight
    assert end.x[1] - end.x[0] == pytest.approx(42.0, abs=1e-12)
    assert end.y[1] == end.y[0]


@settings(max_examples=60, deadline=None)
@given(lo=st.floats(-5, 5), width=st.floats(0.0, 10.0), n=st.integers(1, 50),
       points=st.lists(st.floats(-20, 20), max_size=5), on_grid=st.lists(
           st.integers(0, 50), max_size=3))
def test_with_points_is_unique_of_the_concatenation(lo: float, width: float, n: int,
                                                    points: list[float],
                                                    on_grid: list[int]) -> None:
    from datasets.cutin_model import _with_points

    base = np.linspace(lo, lo + width, n + 1)
    pts = points + [float(base[min(i, n)]) for i in on_grid]  # some exactly on the grid
    np.testing.assert_array_equal(_with_points(base, pts),
                                  np.unique(np.concatenate([base, pts])))


def _quad_reference(p: CutInParams, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x(t), y(t) for 0 <= t <= 2 p_t by scipy's adaptive quadrature (QUADPACK), the
    pulse edges as break points, to 1e-13: a reference independent of the rule."""
    from scipy.integrate import quad

    amp = p.p_y1 * p.p_t / math.pi

    def f(s: float, trig: object) -> float:
        return float(speed(p, s)) * trig(amp * (1.0 - math.cos(math.pi * s / p.p_t)))  # type: ignore[operator]

    kinks = [k for k in (p.p_a2, p.p_a2 + p.p_a3) if 0.0 < k < 2.0 * p.p_t]
    out = []
    for trig in (math.cos, math.sin):
        out.append(np.array([quad(f, 0.0, float(b), args=(trig,), epsabs=1e-13,
                                  epsrel=1e-13, limit=200,
                                  points=[k for k in kinks if k < b] or None)[0]
                             for b in t]))
    return out[0], out[1]


@settings(max_examples=30, deadline=None)
@given(p_y1=st.floats(-0.3, 0.3).filter(lambda v: abs(v) > 1e-3), p_t=st.floats(0.5, 5.0),
       p_a1=st.floats(-2.0, 2.0), p_a2=st.floats(-3.0, 6.0), p_a3=st.floats(0.0, 4.0),
       p_v0=st.floats(5.0, 40.0), n=st.integers(1, 40))
def test_motion_equals_adaptive_quadrature(p_y1: float, p_t: float, p_a1: float,
                                           p_a2: float, p_a3: float, p_v0: float,
                                           n: int) -> None:
    """Gauss-Legendre on the panels against QUADPACK to 1e-9 m at any times of the lane
    change (the previous 1 ms trapezoid was off by up to ~1e-5 m on model draws)."""
    p = CutInParams(p_y1=p_y1, p_t=p_t, p_a1=p_a1, p_a2=p_a2, p_a3=p_a3, p_v0=p_v0, dv=1.0,
                    gap=10.0)
    t = np.linspace(0.0, 2.0 * p_t, n + 1)[1:] * np.linspace(0.999, 1.0, n)
    if bool((speed(p, np.linspace(0.0, 2.0 * p_t, 200)) < 0).any()):
        return  # a reversing cutter is no cut-in
    m = motion(p, t)
    x_ref, y_ref = _quad_reference(p, t)
    np.testing.assert_allclose(m.x, x_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(m.y, y_ref, rtol=0, atol=1e-9)


def test_small_heading_closed_forms_by_hand() -> None:
    """Constant speed v and a small heading amplitude A = p_y1 p_t / pi (psi = A (1 - cos
    w t), w = pi / p_t, psi <= 6e-5 rad): y = v A (t - sin(w t) / w) up to v psi^3 / 6 t
    (< 6e-12 m) and x = v (t - A^2 / 2 (3 t / 2 - 2 sin(w t) / w + sin(2 w t) / (4 w))) up
    to v psi^4 / 24 t. The previous 1 ms trapezoid misses y by ~1e-10 m here."""
    p_t, v = 2.5, 30.0
    p = CutInParams(p_y1=3e-5 * math.pi / p_t, p_t=p_t, p_a1=0.0, p_a2=0.0, p_a3=0.0,
                    p_v0=v, dv=1.0, gap=10.0)
    a, w = 3e-5, math.pi / p_t
    t = np.array([0.05, 0.37, 1.0, 2.5, 3.9, 5.0])
    m = motion(p, t)
    y = v * a * (t - np.sin(w * t) / w)
    x = v * (t - 0.5 * a * a * (1.5 * t - 2.0 * np.sin(w * t) / w
                                + np.sin(2 * w * t) / (4 * w)))
    np.testing.assert_allclose(m.y, y, rtol=0, atol=2e-11)
    np.testing.assert_allclose(m.x, x, rtol=0, atol=1e-11)


def test_no_heading_is_the_exact_straight_integral() -> None:
    """p_y1 = 0: x is the integral of the speed; the rule is exact for the piecewise
    linear speed (its kinks are panel edges): constant 20 m/s gives 20 t, a 1 m/s^2 pulse
    from 1 s to 3 s adds (t - 1)^2 / 2 then 2 (t - 2)."""
    flat = CutInParams(p_y1=0.0, p_t=2.5, p_a1=0.0, p_a2=0.0, p_a3=0.0, p_v0=20.0, dv=1.0,
                       gap=10.0)
    t = np.array([0.0, 0.013, 0.5, 1.234, 4.999, 5.0])
    m = motion(flat, t)
    np.testing.assert_allclose(m.x, 20.0 * t, rtol=0, atol=1e-12)
    assert (m.y == 0.0).all()
    pulse = CutInParams(p_y1=0.0, p_t=2.5, p_a1=1.0, p_a2=1.0, p_a3=2.0, p_v0=20.0, dv=1.0,
                        gap=10.0)
    t = np.array([0.5, 1.0, 1.7, 3.0, 4.2])
    want = 20.0 * t + np.where(t < 1.0, 0.0, np.where(t < 3.0, 0.5 * (t - 1.0) ** 2,
                                                      2.0 + 2.0 * (t - 3.0)))
    np.testing.assert_allclose(motion(pulse, t).x, want, rtol=0, atol=1e-12)
