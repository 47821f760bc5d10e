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
    assert s.t.shape == (101,)
    np.testing.assert_allclose(s.t[[0, 1, 100]], [0.0, 0.1, 10.0])
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
    s = build_scenario(params, lead_in=2.0, dt=0.05, duration=8.0)
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
    [({"dt": 0}, "dt"), ({"duration": -1}, "duration"), ({"lead_in": 10.0}, "lead_in"),
     ({"duration": 10.05}, "whole number"), ({"ego_size": (4.5,)}, "ego_size"),
     ({"cutter_size": (4.5, -1)}, "cutter_size"), ({"lane_width": float("nan")}, "lane_width")],
)
def test_bad_settings(kwargs: dict[str, object], fragment: str) -> None:
    with pytest.raises(BuilderError, match=fragment):
        build_scenario(base_params(), **kwargs)  # type: ignore[arg-type]


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
