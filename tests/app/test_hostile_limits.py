"""Issue 14 items 10 and 11: integers out of range are 422 (never a 500), and requests for
unbounded work are refused up front, naming the limit."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from app.limits import INDEX_MAX

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = json.loads((ROOT / "examples" / "cut-in.json").read_text())


@pytest.fixture(scope="module")
def catalogue_id(client: Any) -> str:
    from tests.app.factories import wait_for

    r = client.post("/catalogues", json={"n": 3, "seed": 1, "score": False})
    assert r.status_code == 202, r.text
    cid: str = r.json()["id"]
    wait_for(lambda: client.get(f"/catalogues/{cid}").json()["status"] == "done",
             "the catalogue")
    return cid


def _is_422(r: Any, field_part: str) -> None:
    assert r.status_code == 422, (r.status_code, r.text[:300])
    assert field_part in (r.json()["error"]["field"] or ""), r.json()


# --------------------------------------------------------------------------- item 10
@pytest.mark.slow
@pytest.mark.parametrize("offset", [str(2**63), str(INDEX_MAX + 1), "-1"])
def test_huge_offsets_are_422(client: Any, catalogue_id: str, offset: str) -> None:
    _is_422(client.get(f"/catalogues/{catalogue_id}/scenarios", params={"offset": offset}),
            "offset")
    _is_422(client.get("/datasets/tno-cutin/parameters", params={"offset": offset}), "offset")


def test_the_largest_documented_offset_is_fine(client: Any, catalogue_id: str) -> None:
    r = client.get(f"/catalogues/{catalogue_id}/scenarios", params={"offset": INDEX_MAX})
    assert r.status_code == 200 and r.json()["scenarios"] == []


@pytest.mark.parametrize("index", [str(10**20), str(INDEX_MAX + 1), "-1"])
def test_dashboard_scenario_index_out_of_range_is_422(client: Any, catalogue_id: str,
                                                      index: str) -> None:
    _is_422(client.get(f"/dashboard/api/catalogues/{catalogue_id}/scenarios/{index}"),
            "index")


def test_integer_bounds_are_in_the_openapi(client: Any) -> None:
    spec = client.get("/openapi.json").json()
    for path, name in [("/catalogues/{catalogue_id}/scenarios", "offset"),
                       ("/datasets/{dataset_id}/parameters", "offset"),
                       ("/dashboard/api/catalogues/{catalogue_id}/scenarios/{index}", "index")]:
        params = {p["name"]: p for p in spec["paths"][path]["get"]["parameters"]}
        schema = params[name]["schema"]
        assert schema["minimum"] == 0 and schema["maximum"] == INDEX_MAX, (path, schema)


@pytest.mark.parametrize(("value", "words"), [(0, "100.."), (10**10, "SCENGEN_MODEL_REPORT"),
                                              (2.5, "integer"), ("many", "integer")])
def test_model_report_samples_out_of_range_is_422(client: Any, value: Any,
                                                  words: str) -> None:
    r = client.post("/models", json={"options": {"n_report_samples": value}})
    _is_422(r, "body.options.n_report_samples")
    assert words in r.json()["error"]["message"]


# --------------------------------------------------------------------------- item 11
def test_too_many_constraints_are_422_naming_the_limit(client: Any) -> None:
    many = ["ttc<3"] * 100_000
    for path in ("/scenarios", "/catalogues"):
        r = client.post(path, json={"n": 1, "constraints": many, "score": False})
        _is_422(r, "body.constraints")
        assert "SCENGEN_CONSTRAINTS_LIMIT" in r.json()["error"]["message"]
    r = client.post("/scenarios", json={"n": 1, "constraints": ["ttc<3" + " " * 500]})
    _is_422(r, "body.constraints.0")
    assert "SCENGEN_CONSTRAINT_LENGTH_LIMIT" in r.json()["error"]["message"]


def test_model_fit_cost_options_are_bounded(client: Any) -> None:
    r = client.post("/models", json={"options": {"n_init": 600}})
    _is_422(r, "body.options.n_init")
    assert "SCENGEN_MODEL_N_INIT_LIMIT" in r.json()["error"]["message"]
    r = client.post("/models", json={"options": {"k_range": [1, 500]}})
    _is_422(r, "body.options.k_range")
    r = client.post("/models", json={"options": {"max_iter": 10**9}})
    _is_422(r, "body.options.max_iter")


def test_posted_scenarios_are_bounded(client: Any) -> None:
    many_objects = copy.deepcopy(EXAMPLE)
    obj = many_objects["objects"][0]
    many_objects["objects"] = [dict(obj, id=f"o{i}") for i in range(100)]
    r = client.post("/risk", json=many_objects)
    _is_422(r, "body.objects")
    assert "SCENGEN_RISK_OBJECTS_LIMIT" in r.json()["error"]["message"]
    many_objects["objects"] = [dict(obj, id=f"o{i}") for i in range(10_000)]
    assert client.post("/risk", json=many_objects).status_code == 413  # the body limit
    long = copy.deepcopy(EXAMPLE)
    long["t"] = [0.1 * k for k in range(20_000)]
    r = client.post("/risk", json=long)
    _is_422(r, "body.t")
    assert "SCENGEN_RISK_STEPS_LIMIT" in r.json()["error"]["message"]


def test_an_oversized_json_body_is_413(client: Any) -> None:
    limit = client.app.state.ctx.settings.body_limit_bytes
    body = b'{"n": 1, "constraints": ["' + b"x" * limit + b'"]}'
    r = client.post("/scenarios", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert str(limit) in r.json()["error"]["message"]


@pytest.mark.parametrize("sampler", ["rejection", "auto", "mcmc"])
def test_an_empty_region_is_422_quickly_for_every_sampler(client: Any, sampler: str) -> None:
    # quickly: the rejection sampler no longer draws 50 million points before it gives up
    # (the test asserts the outcome; the draws it took are in the message)
    r = client.post("/scenarios", json={"n": 2, "constraints": ["gap<5", "gap>6"],
                                        "sampler": sampler, "score": False})
    _is_422(r, "body.constraints")
    assert "empty" in r.json()["error"]["message"]


def test_a_catalogue_of_an_empty_region_is_refused_up_front(client: Any) -> None:
    before = client.get("/catalogues").json()["catalogues"]
    r = client.post("/catalogues", json={"n": 5, "constraints": ["gap<5", "gap>6"],
                                         "sampler": "rejection"})
    _is_422(r, "body.constraints")
    assert client.get("/catalogues").json()["catalogues"] == before


def test_rejection_gives_up_after_the_pilot_on_an_empty_region() -> None:
    from datasets.embedded import default_parameter_table
    from sampler import EmptyRegionError
    from sampler.model.gmm import CutInGMM
    from sampler.sampling import sample

    model = CutInGMM(k_range=(1, 2), n_init=1, cv_folds=2, n_report_samples=200)
    model.fit(default_parameter_table())
    with pytest.raises(EmptyRegionError) as info:
        sample(model, ["gap<5", "gap>6"], 3, 1, "rejection")
    # the pilot's draws, not the 50 million of max_draws
    assert info.value.n_draws < 5_000_000
