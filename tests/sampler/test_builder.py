"""The concrete-scenario builder: geometry by hand, JSON round trip, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets.cutin_model import CutInParams, crossing_time, motion
from riskcore.scenario import ConcreteScenario
from sampler import BuilderError, build_scenario
from tests.sampler.factories import base_params


def test_grid_and_ego_by_hand() -> None:
    s = build_scenario(base_params(), seed=7)
    # constant speeds (25 and 27 m/s); after the lane change (t = 7.5 s) both drive
    # straight, the cutter inside the ego's lane: contact when the bumper gap at t = 8 s
    # has closed at 2 m/s; then the 3 s risk horizon
    gap_8 = s.objects[0].x[80] - s.ego.x[80] - 4.5
    t_contact = 8.0 + gap_8 / 2.0
    assert 9.0 < t_contact < s.provenance["t_cross"] + 12.0 / 2.0  # heading shortened it
    assert s.provenance["resolution"] == "contact"
    assert s.provenance["t_resolved"] == pytest.approx(t_contact, abs=1e-9)
    n = int(np.ceil((t_contact + 3.0) / 0.1))
    assert s.t.shape == (n + 1,)
    np.testing.assert_allclose(s.t[[0, 1, n]], [0.0, 0.1, n * 0.1])
    # no pulse: cutter at 25 m/s always, dv = 2 -> ego at 27 m/s from x = 0 on y = 0
    np.testing.assert_allclose(s.ego.v, 27.0)
    np.testing.assert_allclose(s.ego.x, 27.0 * s.t)
    assert (s.ego.y == 0).all() and (s.ego.psi == 0).all()
    assert s.seed == 7 and s.params == base_params()
    (cutter,) = s.objects
    assert cutter.id == "cutter" and (cutter.length, cutter.width) == (4.5, 1.8)
    # p_y1 > 0 moves left: starts in the right lane centre, straight during the lead-in
    assert cutter.y[0] == -3.75 and cutter.y[25] == -3.75
    assert (cutter.psi[:26] == 0).all()
    np.testing.assert_allclose(cutter.v, 25.0)


def test_gap_and_dv_hold_at_the_crossing_moment() -> None:
    params = base_params(p_a1=-1.5, p_a2=0.5, p_a3=2.0, dv=3.0, gap=9.0)
    s = build_scenario(params, lead_in=2.0, dt=0.05)
    p = CutInParams.from_mapping(params)
    tau_c = crossing_time(p, 3.75 / 2)
    assert s.provenance["t_cross"] == pytest.approx(2.0 + tau_c)
    # evaluate the continuous trajectories at the crossing moment, independently
    m = motion(p, np.array([0.0, tau_c]))
    x_cut0 = s.objects[0].x[40]  # scenario t = 2.0 s = tau 0
    x_cut_c = x_cut0 + m.x[1]
    v_ego = s.ego.v[0]
    gap = x_cut_c - v_ego * (2.0 + tau_c) - 4.5
    assert gap == pytest.approx(9.0, abs=1e-9)
    assert v_ego - m.v[1] == pytest.approx(3.0, abs=1e-12)
    # the cutter's centre is on the marking (y = -lane_width/2) at the crossing moment
    assert -3.75 + motion(p, [tau_c]).y[0] == pytest.approx(-3.75 / 2, abs=1e-3)


def test_right_moving_cutter_starts_left() -> None:
    s = build_scenario(base_params(p_y1=-0.04))
    assert s.objects[0].y[0] == 3.75
    assert s.objects[0].y[-1] < 3.75 / 2
    assert s.provenance["cutter_start_side"] == "left"


def test_json_round_trip_is_lossless() -> None:
    s = build_scenario(base_params(p_a1=0.7, p_a2=-0.3, p_a3=1.1), seed=3,
                       provenance={"sample_index": 4})
    text = json.dumps(s.to_dict())
    back = ConcreteScenario.from_dict(json.loads(text))
    assert back == s
    np.testing.assert_array_equal(back.objects[0].x, s.objects[0].x)
    assert back.provenance["sample_index"] == 4


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [({"dt": 0}, "dt"), ({"duration": -1}, "duration"), ({"lead_in": -1.0}, "lead_in"),
     ({"lead_in": 20.0, "duration": 20.0}, "lead_in"),
     ({"duration": 10.05}, "whole number"), ({"duration": 10.0}, "before the conflict"),
     ({"ego_size": (4.5,)}, "ego_size"),
     ({"cutter_size": (4.5, -1)}, "cutter_size"), ({"lane_width": float("nan")}, "lane_width")],
)
def test_bad_settings(kwargs: dict[str, object], fragment: str) -> None:
    with pytest.raises(BuilderError, match=fragment):
        build_scenario(base_params(), **kwargs)  # type: ignore[arg-type]


def test_duration_ends_when_the_conflict_does() -> None:
    # not closing (dv < 0): settled once the lane change (2 p_t = 5 s after the 2.5 s
    # lead-in) is over, on the first grid step after it (7.6 s), plus the 3 s horizon
    s = build_scenario(base_params(dv=-1.0))
    assert s.provenance["resolution"] == "settled"
    assert s.provenance["t_resolved"] == pytest.approx(7.6, abs=1e-9)
    assert s.t[-1] == pytest.approx(10.6, abs=1e-9)
    # a requested longer duration is kept; a shorter one than the resolution is refused
    assert build_scenario(base_params(dv=-1.0), duration=30.0).t[-1] == pytest.approx(30.0)
    with pytest.raises(BuilderError, match="before the conflict is resolved"):
        build_scenario(base_params(dv=-1.0), duration=7.0)


def test_duration_must_cover_the_cutters_pulse() -> None:
    # contact within a few seconds, but the cutter accelerates from 6 s to 10 s after the
    # start of its lane change (2.5 s lead-in): the motion settles at 12.5 s
    p = base_params(gap=3.0, dv=5.0, p_a1=0.5, p_a2=6.0, p_a3=4.0)
    adaptive = build_scenario(p)
    assert adaptive.provenance["resolution"] == "contact"
    assert adaptive.provenance["t_resolved"] < 8.0 <= 12.5 <= adaptive.t[-1]
    with pytest.raises(BuilderError, match=r"pulse are over at 12\.50 s"):
        build_scenario(p, duration=8.0)
    assert build_scenario(p, duration=12.5).t[-1] == pytest.approx(12.5)


def test_cutter_left_behind() -> None:
    # a lane change that ends straddling the marking 1.85 m from the ego-lane centre does
    # not overlap the ego's 1.8 m wide box (half widths 0.9 + 0.9): closing at 3 m/s the
    # ego passes it; resolved when the cutter's front passes the ego's rear
    p = base_params(dv=3.0, gap=5.0)
    p["p_y1"] = 1.90 * np.pi / (2.0 * 25.0 * 2.5**2)  # displacement ~1.90 m
    s = build_scenario(p)
    end_offset = abs(s.objects[0].y[-1])
    assert 1.8 < end_offset < 3.75 / 2
    assert s.provenance["resolution"] == "left_behind"
    t_r = s.provenance["t_resolved"]
    x_front = np.interp(t_r, s.t, s.objects[0].x) + 2.25
    x_rear = np.interp(t_r, s.t, s.ego.x) - 2.25
    assert x_front == pytest.approx(x_rear, abs=1e-6)


@pytest.mark.parametrize(
    ("params", "fragment"),
    [(base_params(p_y1=0.0), "p_y1"), (base_params(p_y1=0.002), "never reaches"),
     (base_params(dv=-30.0), "ego speed"), (base_params(p_t=-1.0), "p_t"),
     ({"p_y1": 0.1}, "missing"), (base_params(p_a1=-9.0, p_a2=4.0, p_a3=4.0), "negative")],
)
def test_bad_params(params: dict[str, float], fragment: str) -> None:
    with pytest.raises(BuilderError, match=fragment):
        build_scenario(params)


@settings(max_examples=25, deadline=None)
@given(gap=st.floats(0.5, 80.0), dv=st.floats(-5.0, 8.0), p_v0=st.floats(15.0, 38.0),
       side=st.sampled_from([-1.0, 1.0]))
def test_property_gap_at_crossing(gap: float, dv: float, p_v0: float, side: float) -> None:
    params = base_params(gap=gap, dv=dv, p_v0=p_v0, p_y1=side * 0.04 * (25.0 / p_v0))
    s = build_scenario(params)
    t_c = s.provenance["t_cross"]
    # interpolate both centres at the crossing moment (constant speeds: linear is exact
    # for the ego and accurate to the 0.1 s grid's curvature error for the cutter)
    x_ego = np.interp(t_c, s.t, s.ego.x)
    x_cut = np.interp(t_c, s.t, s.objects[0].x)
    assert x_cut - x_ego - 4.5 == pytest.approx(gap, abs=1e-3)
    assert np.isfinite(s.objects[0].x).all()


def test_time_grid_has_no_float_noise_in_its_json() -> None:
    # 3 x 0.1 is 0.30000000000000004 in floating point; the scenario's JSON (and so every
    # export) must read 0.3, 0.7, ... : each step is the float nearest its decimal value
    s = build_scenario(base_params(), seed=7)
    text = json.dumps(s.to_dict()["t"])
    assert "0.30000000000000004" not in text
    for k, tk in enumerate(s.t):
        assert repr(float(tk)) == repr(float(f"{k * 0.1:.6f}")), k
