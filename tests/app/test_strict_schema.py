"""A schema as strict as the validation (issue 27 item 5, finding 5): each finding as
written, re-run; each test fails before the fix."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from sampler.region import constraint_pattern
from tests.app.routes.test_risk import _scenario

ROOT = Path(__file__).resolve().parents[2]


def test_a_fullwidth_digit_in_a_constraint_is_refused(client: Any) -> None:
    r = client.post("/scenarios", json={"n": 1, "constraints": ["ttc<３"], "score": False})
    assert r.status_code == 422, r.text[:200]  # before: 200, read as ttc<3
    assert r.json()["error"]["field"] == "body.constraints.0"
    assert "ASCII digits" in r.json()["error"]["message"]


def test_minus_infinity_is_refused_as_a_filter_like_plus_infinity(client: Any) -> None:
    cid = client.post("/catalogues", json={"n": 1, "score": False}).json()["id"]
    for q in ("btn_min=-inf", "btn_max=inf", "btn_min=nan", "btn_min=１"):
        r = client.get(f"/catalogues/{cid}/scenarios?{q}")
        assert r.status_code == 422, (q, r.text[:200])  # before: 200 for -inf, inf, １
        assert r.json()["error"]["field"] == f"query.{q.split('=')[0]}"
    assert client.get(f"/catalogues/{cid}/scenarios?ttc_min=inf").status_code == 422
    assert client.get(f"/catalogues/{cid}/scenarios?btn_min=0.5").status_code == 200


def test_subset_sampling_without_constraints_is_refused_before_the_job(client: Any) -> None:
    for sampler in ("subset-is", "subset"):
        r = client.post("/catalogues", json={"n": 2, "constraints": [], "sampler": sampler,
                                             "score": False})
        assert r.status_code == 422, r.text[:200]  # before: 202, then a failed job
        assert r.json()["error"]["field"] == "body.constraints"
        assert "needs at least one constraint" in r.json()["error"]["message"]
    # POST /scenarios refused it already (the same words from the sampler)
    r = client.post("/scenarios", json={"n": 1, "constraints": [], "sampler": "subset-is"})
    assert r.status_code == 422


def test_a_body_that_is_not_json_is_400_naming_what_could_not_be_parsed(client: Any) -> None:
    r = client.post("/scenarios", content=b'{"n": 3,',
                    headers={"content-type": "application/json"})
    assert r.status_code == 400, r.text[:200]  # before: 422 naming 'body.8'
    err = r.json()["error"]
    assert err["field"] == "body" and "could not be parsed as JSON at character 8" in \
        err["message"]
    r = client.post("/datasets", content=b"abc",
                    headers={"content-type": "multipart/form-data"})
    assert r.status_code == 400
    err = r.json()["error"]
    assert err["field"] == "body"  # before: null
    assert "multipart/form-data" in err["message"] and "boundary" in err["message"]


def test_docs_error_table_lists_the_400_for_an_unparseable_body() -> None:
    table = (ROOT / "docs" / "api.md").read_text()
    assert re.search(r"^\| 400 \| the body cannot be parsed", table, re.M)


def test_the_openapi_schema_carries_the_grammar_enums_and_the_risk_body(client: Any) -> None:
    spec = client.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    for name in ("CatalogueRequest", "ScenarioRequest", "EvaluationRequest"):
        items = schemas[name]["properties"]["constraints"]["items"]
        assert items["pattern"] == constraint_pattern(), name
    params = {p["name"]: p["schema"] for p in
              spec["paths"]["/catalogues/{catalogue_id}/scenarios"]["get"]["parameters"]}
    assert "btn" in params["order_by"]["enum"] and "index" in params["order_by"]["enum"]
    array = next(s for s in params["class"]["anyOf"] if s.get("type") == "array")
    assert array["items"]["enum"] == ["no_conflict", "preventable", "unpreventable",
                                      "unavoidable"]
    runs = {p["name"]: p["schema"] for p in
            spec["paths"]["/evaluations/{evaluation_id}/runs"]["get"]["parameters"]}
    assert runs["order_by"]["enum"][0] == "run"
    body = spec["paths"]["/risk"]["post"]["requestBody"]["content"]["application/json"]
    assert body["schema"]["required"] == ["t", "ego"]  # before: any object
    assert body["schema"]["additionalProperties"] is False
    from riskcore.scenario import SCHEMA

    assert body["schema"]["properties"]["schema"]["enum"] == [SCHEMA]


def test_a_risk_series_value_must_be_a_json_number(client: Any) -> None:
    scenario = _scenario(cutter_y=11.0, cutter_x0=500.0, cutter_v=35.0)
    scenario["t"] = [scenario["t"][0], str(scenario["t"][1]), *scenario["t"][2:]]
    r = client.post("/risk", json=scenario)
    assert r.status_code == 422, r.text[:200]  # before: 200, "0.1" read as a number
    assert r.json()["error"]["field"] == "body.t[1]"
    scenario = _scenario(cutter_y=11.0, cutter_x0=500.0, cutter_v=35.0)
    scenario["ego"]["v"][0] = True
    r = client.post("/risk", json=scenario)
    assert r.status_code == 422 and r.json()["error"]["field"] == "body.ego.v[0]"


def test_the_constraints_query_string_has_the_grammar_too(client: Any) -> None:
    """GET /models/compare, the dashboard's shift and rates take constraints as one string
    (';', ',' or '&' between them): its pattern accepts what the parser accepts."""
    from app.services.sampling import split_constraints
    from sampler import parse_constraint
    from sampler.errors import ConstraintError

    spec = client.get("/openapi.json").json()
    params = {p["name"]: p["schema"] for p in
              spec["paths"]["/dashboard/api/models/{model_id}/shift"]["get"]["parameters"]}
    pattern = re.compile(params["constraints"]["pattern"])
    for text in ["ttc<3", "ttc<3; btn>0.7", " ttc<3 ,v_ego>=20 & gap<30 ", "", ";",
                 "support==inside; ttc<2"]:
        assert pattern.match(text), text
        for part in split_constraints(text):
            parse_constraint(part)
    for text in ["ttc<３", "ttc<3;; foo<1", "ttc<3 btn>1", "ttc<inf"]:
        assert not pattern.match(text), text
        try:
            for part in split_constraints(text):
                parse_constraint(part)
        except ConstraintError:
            continue
        raise AssertionError(f"{text!r} parsed")
    r = client.get("/dashboard/api/models/default/shift", params={"constraints": "ttc<３"})
    assert r.status_code == 422
