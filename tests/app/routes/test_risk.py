"""POST /risk: score a posted concrete scenario (hand-made cases) and refuse bad ones."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest


def _scenario(cutter_y: float, cutter_x0: float, cutter_v: float) -> dict[str, Any]:
    t = np.round(np.arange(0, 4.01, 0.1), 10)
    ego_v = 30.0

    def track(tid: str, x0: float, y: float, v: float) -> dict[str, Any]:
        return {"id": tid, "length": 4.5, "width": 1.8,
                "x": (x0 + v * t).tolist(), "y": [y] * len(t), "psi": [0.0] * len(t),
                "v": [v] * len(t), "a": None, "yaw_rate": None}

    return {"schema": "scengen.concrete-scenario/1", "t": t.tolist(),
            "ego": track("ego", 0.0, 0.0, ego_v),
            "objects": [track("car", cutter_x0, cutter_y, cutter_v)],
            "params": {}, "seed": None, "provenance": {"source": "test drive"}}


def test_a_far_away_car_is_no_risk(client: Any) -> None:
    # 500 m ahead, three lanes to the left, driving away: nothing can collide
    r = client.post("/risk", json=_scenario(cutter_y=11.0, cutter_x0=500.0, cutter_v=35.0))
    assert r.status_code == 200, r.text
    summary = r.json()["summary"]
    assert summary["risk"] == 0.0
    assert summary["min_ttr"] == "Infinity"  # no predicted collision (the JSON convention)


def test_a_stopped_car_just_ahead_in_the_ego_lane_is_high_risk(client: Any) -> None:
    # 15 m ahead at standstill, ego at 30 m/s: the collision comes in 0.5 s
    r = client.post("/risk", json=_scenario(cutter_y=0.0, cutter_x0=19.5, cutter_v=0.0))
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["summary"]["risk"] > 0.5
    assert max(body["series"]["r_dep"]) == body["summary"]["risk"]
    # issue 25: the summary says which ego it describes (one that never reacts)
    assert body["summary"]["ego"].startswith("scripted: the ego drives its track as given "
                                             "and never reacts")
    assert "samples" not in body["objects"][0]  # the summary by default (issue 13)
    full = client.post("/risk", params={"samples": True},
                       json=_scenario(cutter_y=0.0, cutter_x0=19.5, cutter_v=0.0)).json()
    assert full["series"] == body["series"]
    ttr = full["objects"][0]["samples"]["ttr"]
    assert len(ttr) == len(body["series"]["t"]) and len(ttr[0]) == 100


@pytest.mark.parametrize(("mutate", "field"), [
    (lambda s: s.pop("ego"), "body.ego"),
    (lambda s: s["ego"]["x"].pop(), "body.ego.x"),
    (lambda s: s.update(colour="red"), "body"),
    (lambda s: s["objects"][0].update(width=-1.0), "body.objects[0].width"),
    (lambda s: s.update(t=[0.0]), "body.t"),
])
def test_bad_scenarios_are_422_naming_the_field(client: Any, mutate: Any, field: str) -> None:
    scenario = _scenario(0.0, 50.0, 20.0)
    mutate(scenario)
    r = client.post("/risk", json=scenario)
    assert r.status_code == 422, r.text
    assert r.json()["error"]["field"] == field


def test_not_a_json_object_is_422(client: Any) -> None:
    r = client.post("/risk", json=[1, 2, 3])
    assert r.status_code == 422 and r.json()["error"]["field"] == "body"
