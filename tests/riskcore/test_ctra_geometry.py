"""CTRA rollout (eq. 1) and oriented-box geometry: hand cases, ODE and corner references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from riskcore import boxes_overlap, ctra_states, time_headway, ttc_constant_velocity
from tests.riskcore.reference import ref_overlap

finite = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}


# --- CTRA ------------------------------------------------------------------------------


def test_straight_constant_speed() -> None:
    x, y, psi, v = ctra_states(1.0, 2.0, 0.0, 10.0, 0.0, 0.0, 2.0)
    assert (float(x), float(y), float(psi), float(v)) == (21.0, 2.0, 0.0, 10.0)


def test_straight_constant_acceleration_along_a_heading() -> None:
    x, y, _, v = ctra_states(0.0, 0.0, math.pi / 2, 10.0, 2.0, 0.0, 3.0)
    assert math.isclose(float(y), 39.0, rel_tol=1e-15)  # 10·3 + 2·9/2
    assert abs(float(x)) < 1e-14
    assert float(v) == 16.0


def test_quarter_circle_at_constant_speed() -> None:
    # R = v/ω = 20 m; φ = ωτ = π/2: from (0, 0) heading +x to (20, 20) heading +y
    x, y, psi, v = ctra_states(0.0, 0.0, 0.0, 10.0, 0.0, 0.5, math.pi)
    assert math.isclose(float(x), 20.0, rel_tol=1e-14)
    assert math.isclose(float(y), 20.0, rel_tol=1e-14)
    assert math.isclose(float(psi), math.pi / 2, rel_tol=1e-15)
    assert float(v) == 10.0


def test_braking_stops_and_stays() -> None:
    # 10 m/s at -5 m/s² stops after 2 s and 10 m, also when turning
    x, y, psi, v = ctra_states(0.0, 0.0, 0.0, 10.0, -5.0, 0.0, np.array([1.0, 2.0, 5.0]))
    np.testing.assert_allclose(x, [7.5, 10.0, 10.0], rtol=1e-15)
    np.testing.assert_array_equal(v, [5.0, 0.0, 0.0])
    _, _, psi_t, _ = ctra_states(0.0, 0.0, 0.0, 10.0, -5.0, 0.3, np.array([2.0, 9.0]))
    assert psi_t[0] == psi_t[1] == pytest.approx(0.6)
    # at standstill with a <= 0 nothing moves or turns
    x, y, psi, v = ctra_states(3.0, 4.0, 1.0, 0.0, 0.0, 0.5, 2.0)
    assert (float(x), float(y), float(psi), float(v)) == (3.0, 4.0, 1.0, 0.0)


def test_the_small_turn_limit_is_continuous() -> None:
    tau = 3.0
    straight = ctra_states(0.0, 0.0, 0.3, 20.0, 1.5, 0.0, tau)
    tiny = ctra_states(0.0, 0.0, 0.3, 20.0, 1.5, 1e-12, tau)
    for q0, q1 in zip(straight, tiny, strict=True):
        assert abs(float(q0) - float(q1)) < 1e-9
    # across the switch from the series to the closed form at |ωτ| = 0.1
    below = ctra_states(0.0, 0.0, 0.3, 20.0, 1.5, 0.1 / tau * (1 - 1e-12), tau)
    above = ctra_states(0.0, 0.0, 0.3, 20.0, 1.5, 0.1 / tau * (1 + 1e-12), tau)
    for q0, q1 in zip(below, above, strict=True):
        assert abs(float(q0) - float(q1)) < 1e-9


def _ode(x0: float, y0: float, psi0: float, v0: float, a: float, w: float,
         tau: float) -> np.ndarray:
    def rhs(_t: float, s: np.ndarray) -> list[float]:
        return [s[3] * math.cos(s[2]), s[3] * math.sin(s[2]), w, a]
    sol = solve_ivp(rhs, (0.0, tau), [x0, y0, psi0, v0], rtol=1e-12, atol=1e-12,
                    method="DOP853")
    return sol.y[:, -1]


@settings(max_examples=40, deadline=None)
@given(psi0=st.floats(-math.pi, math.pi, **finite), v0=st.floats(0.5, 40.0, **finite),
       a=st.floats(0.0, 4.0, **finite), w=st.floats(-1.0, 1.0, **finite),
       tau=st.floats(0.0, 3.0, **finite))
def test_closed_form_matches_numerical_integration(psi0: float, v0: float, a: float,
                                                   w: float, tau: float) -> None:
    """While moving (the model's one departure from eq. (1): no turning at standstill)."""
    got = np.array([float(q) for q in ctra_states(1.0, -2.0, psi0, v0, a, w, tau)])
    np.testing.assert_allclose(got, _ode(1.0, -2.0, psi0, v0, a, w, tau), atol=1e-7)


@settings(max_examples=60, deadline=None)
@given(y0=st.floats(-50, 50, **finite), psi0=st.floats(-3, 3, **finite),
       v0=st.floats(0, 40, **finite), a=st.floats(-8, 4, **finite),
       w=st.floats(-1, 1, **finite), tau=st.floats(0, 3, **finite))
def test_mirroring_is_exact(y0: float, psi0: float, v0: float, a: float, w: float,
                            tau: float) -> None:
    x1, y1, p1, v1 = ctra_states(5.0, y0, psi0, v0, a, w, tau)
    x2, y2, p2, v2 = ctra_states(5.0, -y0, -psi0, v0, a, -w, tau)
    assert (float(x1), float(y1), float(p1), float(v1)) == (float(x2), -float(y2),
                                                            -float(p2), float(v2))


def test_ctra_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="finite"):
        ctra_states(0.0, 0.0, 0.0, math.nan, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="v0 and tau"):
        ctra_states(0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0)


# --- boxes -----------------------------------------------------------------------------


def test_touching_boxes_do_not_overlap() -> None:
    """The convention: only a positive-area intersection is a collision."""
    a = [0.0, 0.0, 0.0, 4.0, 2.0]
    assert not boxes_overlap(a, [4.0, 0.0, 0.0, 4.0, 2.0])  # shared edge (front/rear)
    assert not boxes_overlap(a, [0.0, 2.0, 0.0, 4.0, 2.0])  # shared edge (side)
    assert not boxes_overlap(a, [4.0, 2.0, 0.0, 4.0, 2.0])  # shared corner
    assert boxes_overlap(a, [4.0 - 1e-9, 0.0, 0.0, 4.0, 2.0])
    assert boxes_overlap(a, [0.0, 2.0 - 1e-9, 0.0, 4.0, 2.0])
    assert not boxes_overlap(a, [4.0 + 1e-9, 0.0, 0.0, 4.0, 2.0])


def test_separation_found_only_on_the_other_boxs_axis() -> None:
    # A: 2 x 2 square at the origin; B: the same square turned by 45° at (d, d), its edge
    # facing A at distance 1 from its centre along (1, 1)/√2. On A's axes they overlap while
    # d < 1 + √2 = 2.41; on B's diagonal axis they separate once d ≥ 1 + 1/√2 = 1.71.
    a = [0.0, 0.0, 0.0, 2.0, 2.0]
    assert not boxes_overlap(a, [1.9, 1.9, math.pi / 4, 2.0, 2.0])
    assert boxes_overlap(a, [1.6, 1.6, math.pi / 4, 2.0, 2.0])
    # symmetric in the two arguments
    assert not boxes_overlap([1.9, 1.9, math.pi / 4, 2.0, 2.0], a)


def test_boxes_overlap_broadcasts_and_validates() -> None:
    a = np.tile(np.array([0.0, 0.0, 0.0, 4.0, 2.0]), (3, 1))
    b = np.array([[1.0, 0.0, 0.3, 4.0, 2.0], [10.0, 0.0, 0.0, 4.0, 2.0],
                  [0.0, 1.0, 1.0, 4.0, 2.0]])
    np.testing.assert_array_equal(boxes_overlap(a, b), [True, False, True])
    with pytest.raises(ValueError, match="length and width"):
        boxes_overlap([0, 0, 0, -1.0, 2.0], a[0])
    with pytest.raises(ValueError, match="shape"):
        boxes_overlap([0, 0, 0, 1.0], a[0])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1, 1, **finite), min_size=8, max_size=8))
def test_overlap_matches_the_corner_projection_reference(u: list[float]) -> None:
    rng = np.random.default_rng(abs(hash(tuple(u))) % 2**32)
    n = 120
    a = np.column_stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n),
                         rng.uniform(-4, 4, n), 3 + 2 * abs(u[0]) + rng.uniform(0, 2, n),
                         1.5 + abs(u[1]) + rng.uniform(0, 1, n)])
    b = np.column_stack([rng.uniform(-5, 5, n) + u[2], rng.uniform(-5, 5, n) + u[3],
                         rng.uniform(-4, 4, n) + u[4], 3 + 2 * abs(u[5]) + rng.uniform(0, 2, n),
                         1.5 + abs(u[6]) + rng.uniform(0, 1, n)])
    got = boxes_overlap(a, b)
    want = np.array([ref_overlap(a[i:i + 1, :3], a[i, 3], a[i, 4], b[i:i + 1, :3], b[i, 3],
                                 b[i, 4])[0] for i in range(n)])
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < n  # both outcomes present


def test_ttc_hand_cases() -> None:
    car = (0.0, 0.0, 0.0, 4.5, 1.8)
    # rear-end: 10 m bumper gap, closing at 5 m/s
    assert ttc_constant_velocity(car, 20.0, (14.5, 0.0, 0.0, 4.5, 1.8), 15.0) == 2.0
    # head-on: 25.5 m gap, closing at 20 m/s
    assert math.isclose(float(ttc_constant_velocity(car, 10.0, (30.0, 0.0, math.pi, 4.5, 1.8),
                                                    10.0)), 1.275, rel_tol=1e-12)
    # overlapping now: 0; parallel in the next lane or opening: +inf
    assert ttc_constant_velocity(car, 20.0, (2.0, 0.5, 0.0, 4.5, 1.8), 15.0) == 0.0
    assert ttc_constant_velocity(car, 20.0, (0.0, 3.5, 0.0, 4.5, 1.8), 15.0) == math.inf
    assert ttc_constant_velocity(car, 10.0, (14.5, 0.0, 0.0, 4.5, 1.8), 15.0) == math.inf
    # crossing: B drives up the y axis at x = 20 from y = -10; A reaches x = 20 - 2.25 - 0.9
    # at t = 1.685 s, B's front reaches y = -0.9 at t = (10 - 2.25 - 0.9)/5 = 1.37 s, and
    # it is still in the way at 1.685 s (until (10 + 2.25 + 0.9)/5 = 2.63 s)
    t = float(ttc_constant_velocity(car, 10.0, (20.0, -10.0, math.pi / 2, 4.5, 1.8), 5.0))
    assert math.isclose(t, 1.685, rel_tol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.tuples(*(st.floats(-1, 1, **finite) for _ in range(7))))
def test_ttc_is_the_first_moment_of_overlap(u: tuple[float, ...]) -> None:
    a = (0.0, 0.0, 0.0, 4.5, 1.8)
    b = (20 + 15 * u[0], 6 * u[1], 3.2 * u[2], 4.0 + u[3], 1.9)
    va, vb = 20 + 10 * u[4], 15 + 15 * u[5]
    ttc = float(ttc_constant_velocity(a, va, b, vb))

    def at(t: np.ndarray) -> np.ndarray:
        pa = np.column_stack([a[0] + va * t, 0 * t, 0 * t, 0 * t + a[3], 0 * t + a[4]])
        pb = np.column_stack([b[0] + vb * math.cos(b[2]) * t, b[1] + vb * math.sin(b[2]) * t,
                              0 * t + b[2], 0 * t + b[3], 0 * t + b[4]])
        return boxes_overlap(pa, pb)

    grid = np.linspace(0, 30, 3001)
    hits = grid[at(grid)]
    if math.isinf(ttc):
        assert hits.size == 0
    else:
        assert at(np.array([ttc + 1e-6]))[0]
        assert ttc == 0.0 or not at(np.array([ttc - 1e-6]))[0]
        assert hits.size == 0 or hits[0] >= ttc - 1e-9


def test_time_headway_hand_cases() -> None:
    ego = (0.0, 0.0, 0.0, 4.5, 1.8)
    assert time_headway(ego, 20.0, (34.5, 0.0, 0.0, 4.5, 1.8)) == 1.5  # 30 m at 20 m/s
    assert time_headway(ego, 20.0, (34.5, 1.7, 0.0, 4.5, 1.8)) == 1.5  # still in the path
    assert time_headway(ego, 20.0, (34.5, 3.5, 0.0, 4.5, 1.8)) == math.inf  # next lane
    assert time_headway(ego, 20.0, (-34.5, 0.0, 0.0, 4.5, 1.8)) == math.inf  # behind
    assert time_headway(ego, 0.0, (34.5, 0.0, 0.0, 4.5, 1.8)) == math.inf  # standing
    assert time_headway(ego, 20.0, (3.0, 0.0, 0.0, 4.5, 1.8)) == 0.0  # overlapping
    # a lead turned by 90°: its half extent along the ego is 0.9 m
    assert math.isclose(float(time_headway(ego, 20.0, (34.5, 0.0, math.pi / 2, 4.5, 1.8))),
                        (34.5 - 0.9 - 2.25) / 20.0, rel_tol=1e-12)


@settings(max_examples=30, deadline=None)
@given(psi0=st.floats(-3, 3, **finite), v0=st.floats(0, 40, **finite),
       a=st.lists(st.floats(-9, 4, **finite), min_size=1, max_size=6),
       w=st.floats(-1, 1, **finite))
def test_the_batch_rollout_matches_the_closed_form(psi0: float, v0: float, a: list[float],
                                                   w: float) -> None:
    """The engine's batch rollout (angle-addition recurrence) vs ctra_states per step."""
    from riskcore import kernels as _kernels

    a_arr = np.array(a)
    w_arr = np.full(a_arr.shape, w)
    poses = _kernels.predict(1.0, 2.0, psi0, v0, a_arr, w_arr, 30, 0.1)
    tau = np.arange(31) * 0.1
    for i, ai in enumerate(a):
        x, y, psi, _ = ctra_states(1.0, 2.0, psi0, v0, ai, w, tau)
        np.testing.assert_allclose(poses[i, :, 0], x, rtol=0, atol=1e-11)
        np.testing.assert_allclose(poses[i, :, 1], y, rtol=0, atol=1e-11)
        np.testing.assert_allclose(poses[i, :, 2], np.cos(psi), rtol=0, atol=1e-13)
        np.testing.assert_allclose(poses[i, :, 3], np.sin(psi), rtol=0, atol=1e-13)
