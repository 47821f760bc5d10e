"""The simulator's vehicle model and box geometry (riskcore.sut.ego_advance,
ego_advance_with_onset, band_range, box_clearance; the esmini adapter moves its ego with
the same functions): hand-computed cases, a fine Euler reference, properties, and the box's
x-range in a band against a dense grid of its points."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from riskcore.sut import band_range, box_clearance, ego_advance, ego_advance_with_onset

J = 12.65  # m/s³, the default jerk limit


def test_ego_advance_hand_computed() -> None:
    # no command change: constant speed
    assert ego_advance(3.0, 20.0, 0.0, 0.0, J, 0.5) == (13.0, 20.0, 0.0, False)
    # full brake from cruising, still on the jerk ramp after 0.5 s (9 / 12.65 = 0.71 s):
    # a = -12.65 * 0.5, v = 20 - 12.65 * 0.5^2 / 2, x = 20 * 0.5 - 12.65 * 0.5^3 / 6
    x, v, a, stopped = ego_advance(0.0, 20.0, 0.0, -9.0, J, 0.5)
    assert (x, v, a) == pytest.approx((10.0 - 12.65 / 48.0, 20.0 - 12.65 / 8.0, -6.325))
    assert not stopped
    # the ramp ends after 9 / 12.65 s, then -9 m/s² for the rest of 1 s
    t1 = 9.0 / 12.65
    v1 = 20.0 - 12.65 * t1 ** 2 / 2.0
    x1 = 20.0 * t1 - 12.65 * t1 ** 3 / 6.0
    r = 1.0 - t1
    assert ego_advance(0.0, 20.0, 0.0, -9.0, J, 1.0) == pytest.approx(
        (x1 + v1 * r - 4.5 * r * r, v1 - 9.0 * r, -9.0, False))
    # braking at -9 from 1 m/s: stops after 1/9 s, 1/18 m on; a snaps to 0
    assert ego_advance(0.0, 1.0, -9.0, -9.0, J, 1.0) == pytest.approx(
        (1.0 / 18.0, 0.0, 0.0, True))
    # stopping on the jerk ramp: v = 0.5 - j t^2 / 2 = 0 at t = sqrt(1 / j)
    ts = math.sqrt(1.0 / 12.65)
    assert ego_advance(0.0, 0.5, 0.0, -9.0, J, 0.5) == pytest.approx(
        (0.5 * ts - 12.65 * ts ** 3 / 6.0, 0.0, 0.0, True))
    # at standstill a braking command keeps it there (no reversing)
    assert ego_advance(5.0, 0.0, 0.0, -4.0, J, 0.1) == (5.0, 0.0, 0.0, False)
    # and a positive one starts it on the jerk ramp: a = j t, v = j t^2 / 2, x = j t^3 / 6
    assert ego_advance(0.0, 0.0, 0.0, 3.0, 10.0, 0.2) == pytest.approx(
        (10.0 * 0.008 / 6.0, 0.2, 2.0, False))


def test_ego_advance_stops_where_the_speed_first_falls_to_zero_from_a_rising_start() -> None:
    # from v = 0 with a = 1 m/s² and the command -9: on the ramp a = 1 - j t, so
    # v = t - j t^2 / 2 rises, then falls to 0 at t* = 2 / j = 0.158 s (inside the 0.2 s
    # step, before the ramp's end at 10 / j = 0.79 s); x(t*) = t*^2 / 2 - j t*^3 / 6
    # = t*^2 (1/2 - 1/3) = t*^2 / 6. The kernel used to take the root t = 0 (where v
    # rises), refuse it and run on: x = 0.0031 m, v = 0, a = -1.53 m/s², not stopped.
    ts = 2.0 / J
    assert ego_advance(0.0, 0.0, 1.0, -9.0, J, 0.2) == pytest.approx(
        (ts * ts / 6.0, 0.0, 0.0, True), abs=1e-15)
    # the same from a speed of 1e-20 m/s: the root near 0 (-v / a, behind) is no stop
    # (it used to end the ego there, at x = 0)
    assert ego_advance(0.0, 1e-20, 1.0, -9.0, J, 0.2) == pytest.approx(
        (ts * ts / 6.0, 0.0, 0.0, True), abs=1e-15)
    # a subnormal acceleration: the speed falls to 0 after 2 a / j < 1e-300 s, so the ego
    # stops where it is (it used to back up 1.04 mm: the root hidden by rounding)
    x, v, a, stopped = ego_advance(0.0, 0.0, 5e-324, -1.0, J, 0.125)
    assert (v, a, stopped) == (0.0, 0.0, True)
    assert 0.0 <= x < 1e-300


def test_ego_advance_matches_a_fine_euler_reference() -> None:
    """A slow straightforward reference: 1 µs Euler steps of the same rules."""
    rng = np.random.default_rng(3)
    for k in range(12):  # half of them slow enough to stop within the step
        x, v, a = 0.0, float(rng.uniform(0.0, 30.0 if k % 2 else 1.5)), float(
            rng.uniform(-9.0, 3.0))
        u = float(rng.uniform(-9.0, 3.0))
        tau, j = 0.3, J
        h = 1e-6
        xe, ve, ae = x, v, a
        for _ in range(round(tau / h)):
            if ve <= 0.0 and u <= 0.0 and ae <= 0.0:
                ve, ae = 0.0, 0.0
                break
            ae_next = ae + max(-j * h, min(j * h, u - ae))
            ve_next = ve + 0.5 * (ae + ae_next) * h
            if ve_next <= 0.0 and ae_next < 0.0:
                ve, ae = 0.0, 0.0
                break
            xe += 0.5 * (ve + ve_next) * h
            ve, ae = ve_next, ae_next
        got = ego_advance(x, v, a, u, j, tau)
        assert got[0] == pytest.approx(xe, abs=1e-4)
        assert got[1] == pytest.approx(ve, abs=1e-4)
        assert got[2] == pytest.approx(ae, abs=1e-4)


@given(x=st.floats(-100.0, 100.0), v=st.floats(0.0, 40.0), a=st.floats(-9.0, 3.0),
       u=st.floats(-9.0, 3.0), tau=st.floats(0.0, 0.2))
def test_ego_advance_properties(x: float, v: float, a: float, u: float, tau: float) -> None:
    x1, v1, a1, stopped = ego_advance(x, v, a, u, J, tau)
    assert v1 >= 0.0  # never reverses
    assert x1 >= x - 1e-12  # never backs up
    assert abs(a1 - a) <= J * tau + 1e-9 or (stopped and a1 == 0.0)  # the jerk limit
    if not stopped:  # the acceleration moves towards the command, never past it
        assert min(a, u) - 1e-9 <= a1 <= max(a, u) + 1e-9
    # two half steps are one step (the closed form composes), except that, as in the
    # simulator, coming to a stop ends the step's motion: a positive command restarts
    # the ego only from the next step; and not for steps so short (subnormal) that half
    # of one rounds to 0
    assume(not (stopped and u > 0.0) and (tau == 0.0 or tau > 1e-300))
    xh, vh, ah, _ = ego_advance(x, v, a, u, J, tau / 2)
    x2, v2, a2, _ = ego_advance(xh, vh, ah, u, J, tau / 2)
    assert (x2, v2, a2) == pytest.approx((x1, v1, a1), abs=1e-9)


def test_a_command_from_its_onset_on_is_two_calls() -> None:
    # braking from 0.03 s into a 0.1 s step: 0.03 s at constant speed, then the ramp
    got = ego_advance_with_onset(0.0, 20.0, 0.0, 0.0, -9.0, 0.03, J, 0.1)
    r = 0.07
    assert got == pytest.approx((20.0 * 0.1 - J * r ** 3 / 6.0, 20.0 - J * r * r / 2.0,
                                 -J * r, False))
    # no onset: the new command throughout; an onset past the step: the old one throughout
    assert ego_advance_with_onset(1.0, 10.0, 0.0, 2.0, -3.0, 0.0, J, 0.1) == \
        ego_advance(1.0, 10.0, 0.0, -3.0, J, 0.1)
    assert ego_advance_with_onset(1.0, 10.0, 0.0, 2.0, -3.0, 0.5, J, 0.1) == \
        ego_advance(1.0, 10.0, 0.0, 2.0, J, 0.1)


# ------------------------------------------------------------------------- geometry


def test_band_range_hand_computed() -> None:
    # an axis-aligned box in the band: its own extent
    assert band_range(10.0, 0.0, 0.0, 2.0, 1.0, 1.0) == pytest.approx((True, 8.0, 12.0))
    # beside the band: misses it
    assert not band_range(10.0, 2.5, 0.0, 2.0, 1.0, 1.0)[0]
    # turned by 90°: x-extent = its width
    assert band_range(5.0, 0.0, math.pi / 2, 2.0, 1.0, 1.0) == pytest.approx((True, 4.0, 6.0))
    # a unit square turned by 45° at y = 3: its lowest corner at 3 - sqrt(2) = 1.586 reaches
    # 0.114 m into the band |y| <= 1.7; the part inside is a triangle of half-width
    # 1.7 - (3 - sqrt(2))
    w = 1.7 - (3.0 - math.sqrt(2.0))
    assert band_range(0.0, 3.0, math.pi / 4, 1.0, 1.0, 1.7) == pytest.approx((True, -w, w))


@settings(max_examples=60)
@given(x=st.floats(-10.0, 10.0), y=st.floats(-4.0, 4.0), h=st.floats(-math.pi, math.pi),
       hl=st.floats(0.5, 3.0), hw=st.floats(0.3, 1.2), band=st.floats(0.2, 2.0))
def test_band_range_matches_dense_points_of_the_box(x: float, y: float, h: float, hl: float,
                                                    hw: float, band: float) -> None:
    """A slow reference: a dense grid of the box's points, those inside the band."""
    i, j = np.meshgrid(np.linspace(-1.0, 1.0, 401), np.linspace(-1.0, 1.0, 401))
    px = x + i * hl * math.cos(h) - j * hw * math.sin(h)
    py = y + i * hl * math.sin(h) + j * hw * math.cos(h)
    inside = np.abs(py) <= band
    meets, lo, hi = band_range(x, y, h, hl, hw, band)
    step = 2.0 * (hl + hw) / 400  # the grid's spacing bounds the reference's error
    if not meets:
        assert not inside.any()
        return
    if inside.any():
        assert lo == pytest.approx(px[inside].min(), abs=step)
        assert hi == pytest.approx(px[inside].max(), abs=step)


def test_box_clearance_hand_computed() -> None:
    # ego 4.5 m x 1.8 m at x = 1; a car of the same size straight ahead, 0.1 m free
    near, gap = box_clearance(5.6, 0.0, 0.0, 1.0, 2.25, 0.9, 2.25, 0.9)
    assert near and gap == pytest.approx(0.1)
    # 0.1 m into the ego's front: overlap
    near, gap = box_clearance(5.4, 0.0, 0.0, 1.0, 2.25, 0.9, 2.25, 0.9)
    assert near and gap == pytest.approx(-0.1)
    # beside with a lateral gap of 0.1 m, and wholly behind the ego: not counted
    assert not box_clearance(1.0, 1.9, 0.0, 1.0, 2.25, 0.9, 2.25, 0.9)[0]
    assert not box_clearance(-4.0, 0.0, 0.0, 1.0, 2.25, 0.9, 2.25, 0.9)[0]
