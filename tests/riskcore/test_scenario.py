"""The concrete-scenario type: validation messages and the lossless JSON round trip."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riskcore.scenario import SCHEMA, ConcreteScenario, ScenarioError


def _track(n: int, track_id: str = "ego", dy: float = 0.0) -> dict[str, object]:
    return {
        "id": track_id, "length": 4.5, "width": 1.8,
        "x": [float(i) for i in range(n)], "y": [dy] * n, "psi": [0.0] * n, "v": [10.0] * n,
    }


def _scenario(n: int = 3) -> dict[str, object]:
    return {"t": [0.1 * i for i in range(n)], "ego": _track(n),
            "objects": [_track(n, "car1", 3.5)], "params": {"gap": 10.0}, "seed": 4,
            "provenance": {"source": "hand-made"}}


def test_round_trip_through_json_text_is_lossless() -> None:
    sc = ConcreteScenario.from_dict(_scenario())
    again = ConcreteScenario.from_dict(json.loads(json.dumps(sc.to_dict())))
    assert again == sc
    assert again.to_dict()["schema"] == SCHEMA
    assert again.objects[0].y[0] == 3.5
    assert again.ego.a is None


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=2,
                max_size=20))
def test_any_finite_float_survives_the_round_trip(values: list[float]) -> None:
    n = len(values)
    data = _scenario(n)
    ego = data["ego"]
    assert isinstance(ego, dict)
    ego["y"] = values
    sc = ConcreteScenario.from_dict(data)
    back = ConcreteScenario.from_dict(json.loads(json.dumps(sc.to_dict())))
    assert np.array_equal(back.ego.y, np.asarray(values))


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d["ego"].update(length=-1.0), "ego.length"),
        (lambda d: d["ego"].update(width=0), "ego.width"),
        (lambda d: d["ego"]["x"].__setitem__(1, math.nan), "ego.x[1]"),
        (lambda d: d["objects"][0]["v"].pop(), "objects[0].v: has 2 values"),
        (lambda d: d.update(t=[0.0, 0.2, 0.1]), "t[2]"),
        (lambda d: d.update(t=[0.0, 0.0, 0.1]), "strictly increasing"),
        (lambda d: d.update(colour="red"), "unknown field(s) colour"),
        (lambda d: d["ego"].update(mass=1500), "ego: unknown field(s) mass"),
        (lambda d: d["objects"][0].update(id="ego"), "ids must be unique"),
        (lambda d: d.pop("ego"), "ego: missing"),
        (lambda d: d.update(seed="one"), "seed"),
        (lambda d: d["objects"][0].update(psi="fast"), "objects[0].psi"),
    ],
)
def test_bad_input_names_the_field(mutate: object, message: str) -> None:
    data = json.loads(json.dumps(_scenario()))
    mutate(data)  # type: ignore[operator]
    with pytest.raises(ScenarioError, match=None) as info:
        ConcreteScenario.from_dict(data)
    assert message in str(info.value)


def test_direct_construction_is_validated_too() -> None:
    good = ConcreteScenario.from_dict(_scenario())
    with pytest.raises(ScenarioError, match="strictly increasing"):
        ConcreteScenario(t=np.array([0.0, 0.0, 0.1]), ego=good.ego, objects=good.objects)
