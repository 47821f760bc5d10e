"""evaluate_scenario: the ego's future from the recording, the objects' inputs, the output."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from riskcore import (
    ConcreteScenario,
    RiskSettings,
    SceneError,
    Track,
    ego_future_at,
    evaluate_scenario,
    object_inputs,
)
from tests.riskcore.factories import paper_like_surfaces, straight_track, two_vehicle_scenario


def test_ego_future_interpolates_then_extrapolates_at_constant_velocity() -> None:
    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    # speeding up and turning left: x, y, psi, v all change
    ego = Track("ego", 4.5, 1.8, x=np.array([0.0, 5.0, 11.0, 18.0, 26.0]),
                y=np.array([0.0, 0.1, 0.3, 0.6, 1.0]), psi=np.array([0.0, 0.05, 0.1, 0.15, 0.2]),
                v=np.array([10.0, 11.0, 12.0, 13.0, 14.0]))
    s = RiskSettings(horizon=1.0, dt=0.25)
    fut = ego_future_at(t, ego, 1.25, s)  # times 1.25, 1.5, 1.75, 2.0, 2.25
    np.testing.assert_allclose(fut.x[:4], [14.5, 18.0, 22.0, 26.0])
    np.testing.assert_allclose(fut.v[:4], [12.5, 13.0, 13.5, 14.0])
    np.testing.assert_allclose(fut.psi[:4], [0.125, 0.15, 0.175, 0.2])
    # past the end: constant velocity and heading from the last recorded state
    assert math.isclose(fut.x[4], 26.0 + 14.0 * math.cos(0.2) * 0.25, rel_tol=1e-14)
    assert math.isclose(fut.y[4], 1.0 + 14.0 * math.sin(0.2) * 0.25, rel_tol=1e-14)
    assert fut.psi[4] == 0.2 and fut.v[4] == 14.0


def test_heading_is_unwrapped_before_interpolating() -> None:
    t = np.array([0.0, 1.0])
    ego = Track("ego", 4.5, 1.8, x=np.zeros(2), y=np.zeros(2),
                psi=np.array([math.pi - 0.1, -math.pi + 0.1]), v=np.zeros(2))
    fut = ego_future_at(t, ego, 0.0, RiskSettings(horizon=1.0, dt=0.5))
    assert math.isclose(fut.psi[1], math.pi, rel_tol=1e-12)  # not 0


def test_object_inputs_from_recorded_or_differenced_motion() -> None:
    t = np.linspace(0.0, 2.0, 11)
    tr = Track("o", 4.5, 1.8, x=t * 0, y=t * 0, psi=3.0 + 0.1 * t, v=10.0 + 2.0 * t)
    a0, w0 = object_inputs(t, tr)
    np.testing.assert_allclose(a0, 2.0, rtol=1e-12)
    np.testing.assert_allclose(w0, 0.1, rtol=1e-9)  # ψ crosses π: unwrapped
    given = Track("o", 4.5, 1.8, x=t * 0, y=t * 0, psi=t * 0, v=10.0 + t * 0,
                  a=np.full(11, -1.5), yaw_rate=np.full(11, 0.02))
    a0, w0 = object_inputs(t, given)
    assert np.all(a0 == -1.5) and np.all(w0 == 0.02)


def _closing(t: np.ndarray) -> ConcreteScenario:
    ego = straight_track("ego", t, 0.0, 0.0, 22.0)
    lead = Track("lead", 4.5, 1.8, x=40.0 + 12.0 * t, y=0.4 + 0.05 * t,
                 psi=np.full(t.shape, math.atan2(0.05, 12.0)),
                 v=np.full(t.shape, math.hypot(12.0, 0.05)))
    return two_vehicle_scenario(t, ego, lead)


def test_a_25_hz_recording_gives_the_same_scenes_as_10_hz() -> None:
    """Linear motion: interpolation onto the 0.1 s prediction grid is exact."""
    surf = paper_like_surfaces()
    t10 = np.round(np.arange(0.0, 3.01, 0.1), 12)
    t25 = np.round(np.arange(0.0, 3.001, 0.04), 12)
    r10 = evaluate_scenario(_closing(t10), surfaces=surf)
    r25 = evaluate_scenario(_closing(t25), surfaces=surf)
    common = [(i, int(np.flatnonzero(np.isclose(t25, tt))[0])) for i, tt in enumerate(t10)
              if np.isclose(t25, tt).any()]
    assert len(common) >= 15
    for i, j in common:
        a, b = r10.scenes[i].objects[0], r25.scenes[j].objects[0]
        np.testing.assert_array_equal(a.ttr, b.ttr)
        assert math.isclose(a.risk, b.risk, rel_tol=1e-9, abs_tol=1e-12)
    assert r10.risk > 0.1


def test_result_json_is_plain_and_complete() -> None:
    t = np.round(np.arange(0.0, 2.01, 0.1), 12)
    res = evaluate_scenario(_closing(t), surfaces=paper_like_surfaces())
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)  # no NaN / inf literals anywhere
    back = json.loads(text)
    assert back["format"] == "scengen.scenario-risk/1"
    assert len(back["series"]["t"]) == len(back["series"]["r_dep"]) == 21
    obj = back["objects"][0]
    assert obj["id"] == "lead"
    for key in ("a", "omega", "weight", "ttr", "collision_time", "evasion"):
        arr = obj["samples"][key]
        assert len(arr) == 21 and all(len(row) == 100 for row in arr)
    ttr = [v for row in obj["samples"]["ttr"] for v in row]
    assert None in ttr and any(v is not None for v in ttr)  # +inf written as null
    labels = {v for row in obj["samples"]["evasion"] for v in row}
    assert None in labels and labels - {None}
    assert math.isclose(sum(obj["samples"]["weight"][0]), 1.0, rel_tol=1e-12)
    assert back["summary"] == res.summary()
    assert back["evasion_bits"] == {"steer_left": 1, "steer_right": 2, "brake": 4,
                                    "accelerate": 8}


def test_summary_fields() -> None:
    t = np.round(np.arange(0.0, 2.01, 0.1), 12)
    res = evaluate_scenario(_closing(t), surfaces=paper_like_surfaces())
    s = res.summary()
    assert set(s) == {"risk", "risk_ind", "min_ttr", "min_ttc", "min_wttc", "min_thw",
                      "min_ttr_evasion", "step_of_max_risk", "t_of_max_risk"}
    assert s["risk"] == res.series("r_dep").max() == res.scenes[s["step_of_max_risk"]].r_dep
    assert s["risk"] <= s["risk_ind"] + 1e-12
    assert s["min_ttr"] == min(sc.min_ttr for sc in res.scenes)
    assert s["min_ttc"] == pytest.approx((40 - 4.5 - 10 * 2.0) / 10, rel=1e-3)
    assert isinstance(s["min_ttr_evasion"], str)


def test_no_objects_means_no_risk() -> None:
    t = np.round(np.arange(0.0, 1.01, 0.1), 12)
    sc = ConcreteScenario(t=t, ego=straight_track("ego", t, 0.0, 0.0, 20.0), objects=())
    res = evaluate_scenario(sc)
    assert res.risk == 0.0 and res.risk_ind == 0.0
    s = res.summary()
    assert s["min_ttr"] is None and s["min_ttr_evasion"] is None
    json.dumps(res.to_dict(), allow_nan=False)


def test_negative_speed_is_rejected_naming_the_field() -> None:
    t = np.array([0.0, 0.1, 0.2])
    obj = Track("o", 4.5, 1.8, x=t * 0 + 30, y=t * 0, psi=t * 0, v=np.array([5.0, -1.0, 5.0]))
    sc = ConcreteScenario(t=t, ego=straight_track("ego", t, 0.0, 0.0, 20.0), objects=(obj,))
    with pytest.raises(SceneError, match=r"objects\[0\].v\[1\]"):
        evaluate_scenario(sc)
