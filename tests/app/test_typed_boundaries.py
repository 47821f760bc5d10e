"""Typed boundaries (issue 26 item 5): the objects the services and views return are typed
models, and what they answer is what the dicts they replace answered.

Each test checks one boundary on a real job of the test store: the HTTP response has the
fields (in the order) written out here by hand, it validates against the typed model and
the model writes it back byte for byte (a field gone or of another type fails), and the
values agree with what is counted independently (pages, row counts, the request).
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from tests.app.factories import wait_for

#: GET /catalogues/{id}'s fields in their order (``support`` last: it was an undeclared
#: extra, written after the declared fields)
CATALOGUE_STATUS_FIELDS = [
    "id", "status", "model", "n", "seed", "constraints", "sampler", "score", "wagner_scan",
    "chunk_size", "chunks", "scenarios_stored", "scenarios_done", "progress", "stage",
    "p_region", "rates", "summary", "classes", "error", "created_at", "updated_at",
    "finished_at", "support"]
#: the plain form's order (the CLI and the dashboard's view 3): support after classes
CATALOGUE_PLAIN_FIELDS = [*CATALOGUE_STATUS_FIELDS[:19], "support",
                          *CATALOGUE_STATUS_FIELDS[19:-1]]


def _without_nulls(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_nulls(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_without_nulls(v) for v in value]
    return value


def _ctx(client: Any) -> Any:
    return client.app.state.ctx


@pytest.fixture(scope="module")
def catalogue(client: Any) -> str:
    r = client.post("/catalogues", json={"n": 10, "seed": 7, "constraints": ["ttc<3"]})
    assert r.status_code == 202, r.text
    cid: str = r.json()["id"]
    wait_for(lambda: client.get(f"/catalogues/{cid}").json()["status"] in ("done", "failed"),
             "the catalogue")
    return cid


def test_catalogue_status_is_typed_and_answers_as_before(client: Any, catalogue: str) -> None:
    from app.services import catalogues
    from app.statuses import CatalogueStatus, catalogue_status_plain

    r = client.get(f"/catalogues/{catalogue}")
    body = r.json()
    assert list(body) == CATALOGUE_STATUS_FIELDS
    # the typed model reads the response and writes it back byte for byte
    assert CatalogueStatus.model_validate_json(r.text).model_dump_json() == r.text
    status = catalogues.describe(_ctx(client), catalogue)
    assert isinstance(status, CatalogueStatus)
    assert status.model_dump_json() == r.text
    # values from elsewhere: the request, the scenario pages, the chunking
    assert (body["status"], body["n"], body["seed"]) == ("done", 10, 7)
    assert body["constraints"] == ["ttc<3"] and body["chunks"] == {"total": 2, "done": 2}
    total = client.get(f"/catalogues/{catalogue}/scenarios?limit=1").json()["total"]
    assert body["scenarios_stored"] == body["scenarios_done"] == total == 10
    assert sum(body["classes"].values()) == 10 and sum(body["support"].values()) == 10
    assert body["summary"]["ttc"]["count"] == 10.0  # a float in the response (as before)
    assert isinstance(body["p_region"]["estimate"], float) and body["p_region"]["ci"]

    # the CLI's and view 3's form: the same values, counts as whole numbers, the store's
    # order (support after classes, P(A)'s ci after the sampler's fields)
    plain = catalogue_status_plain(status)
    assert list(plain) == CATALOGUE_PLAIN_FIELDS
    # 10 == 10.0: the values agree; the response adds its declared defaults (null)
    assert _without_nulls(plain) == _without_nulls(body)
    assert type(plain["summary"]["ttc"]["count"]) is int
    assert type(plain["summary"]["ttc"]["mean"]) is float
    keys = list(plain["p_region"])
    assert keys.index("ci") == keys.index("cov") + 1 and keys[:2] == ["estimate", "ci_low"]
    stored = json.loads(json.dumps(plain))
    assert stored["p_region"] == body["p_region"]


def test_catalogue_status_refuses_a_field_it_does_not_declare() -> None:
    from pydantic import ValidationError

    from app.statuses import CatalogueStatus

    with pytest.raises(ValidationError, match="extra"):
        CatalogueStatus.model_validate({"id": "c", "surprise": 1})


#: GET /evaluations/{id}'s fields in their order
EVALUATION_STATUS_FIELDS = [
    "id", "status", "sut", "model", "seed", "constraints", "spec", "runs_planned",
    "runs_done", "progress", "chunks_done", "collisions_so_far", "runs_simulated", "summary",
    "error", "href_runs", "created_at", "updated_at", "finished_at"]


@pytest.fixture(scope="module")
def evaluation(client: Any) -> str:
    r = client.post("/evaluations", json={"sut": "acc", "n": 200, "batch_size": 100,
                                          "seed": 3})
    assert r.status_code == 202, r.text
    eid: str = r.json()["id"]
    wait_for(lambda: client.get(f"/evaluations/{eid}").json()["status"]
             in ("done", "failed"), "the evaluation")
    return eid


def test_evaluation_status_is_typed_and_answers_as_before(client: Any,
                                                         evaluation: str) -> None:
    from app import jsonconv
    from app.services import evaluations
    from app.statuses import EvaluationStatus

    r = client.get(f"/evaluations/{evaluation}")
    body = r.json()
    assert list(body) == EVALUATION_STATUS_FIELDS
    assert EvaluationStatus.model_validate_json(r.text).model_dump_json() == r.text
    status = evaluations.describe(_ctx(client), evaluation)
    assert isinstance(status, EvaluationStatus)
    assert status.model_dump_json() == r.text
    # values from elsewhere: the request, the run pages, the stored row
    assert (body["status"], body["sut"], body["seed"]) == ("done", "acc", 3)
    assert body["spec"]["n"] == 200 and body["spec"]["batch_size"] == 100
    assert (body["runs_planned"], body["runs_done"], body["chunks_done"]) == (200, 200, 2)
    runs = client.get(f"/evaluations/{evaluation}/runs?limit=1").json()["total"]
    assert body["runs_simulated"] == runs > 0
    assert body["href_runs"] == f"/evaluations/{evaluation}/runs"
    # the summary is the stored one, in the service's JSON form
    with _ctx(client).db.read_session() as s:
        from app.db.models import EvaluationRow

        stored = s.get(EvaluationRow, evaluation).summary
    assert body["summary"] == jsonconv.encode(jsonconv.decode(stored))
    assert body["summary"]["runs"] == 200


#: the dashboard's view 3 (a catalogue's criticality), its fields in their order
CRITICALITY_VIEW_FIELDS = [
    "catalogue", "n_rows", "n_scored", "diagnostics", "classes", "n_unscored", "decel_max",
    "btn", "ttr_true", "impact_speed", "r_dep_tp", "alarm_time", "scatter", "top"]
HISTOGRAM_FIELDS = ["edges", "counts", "density", "n", "n_finite", "below", "above",
                    "n_nonfinite", "n_inf", "n_null"]


def test_dashboard_view_3_is_typed_and_answers_as_before(client: Any, catalogue: str) -> None:
    from app.dashboard import views
    from app.dashboard.schemas import CatalogueCriticalityView
    from app.services import catalogues
    from app.statuses import catalogue_status_plain

    r = client.get(f"/dashboard/api/catalogues/{catalogue}/criticality")
    body = r.json()
    assert list(body) == CRITICALITY_VIEW_FIELDS
    assert CatalogueCriticalityView.model_validate_json(r.text).model_dump_json() == r.text
    view = views.catalogue_criticality(_ctx(client), catalogue)
    assert isinstance(view, CatalogueCriticalityView)
    assert view.model_dump_json() == r.text
    for name in ("btn", "ttr_true", "alarm_time"):
        assert list(body[name]) == HISTOGRAM_FIELDS, name
        assert body[name]["n"] == body["n_scored"], name
    assert [d["driver"] for d in body["impact_speed"]] == ["none", "r157_cc", "rss"]
    assert list(body["r_dep_tp"]) == ["scripted", "r157"]
    assert list(body["diagnostics"]) == ["chunks", "methods", "acceptance_mean",
                                         "acceptance_min", "tau_max", "ess_total", "n_draws",
                                         "warnings"]
    assert body["diagnostics"]["chunks"] == 2
    # values from elsewhere: the row count, the status (its plain form), the pages
    assert body["n_rows"] == 10 == body["n_scored"] + body["n_unscored"]
    status = catalogue_status_plain(catalogues.describe(_ctx(client), catalogue))
    assert body["catalogue"] == json.loads(json.dumps(status))
    assert list(body["catalogue"]) == CATALOGUE_PLAIN_FIELDS
    assert {c["name"]: c["count"] for c in body["classes"]} == status["classes"]
    page = client.get(f"/catalogues/{catalogue}/scenarios?limit=10&order_by=btn").json()
    assert [t["index"] for t in body["top"]] == [s["index"] for s in page["scenarios"]]
    assert [t["class"] for t in body["top"]] == [s["class"] for s in page["scenarios"]]
    assert sorted(body["scatter"]["index"]) == sorted(s["index"] for s in page["scenarios"])


#: the dashboard's view 4 (one scenario), its fields in their order
SCENARIO_VIEW_FIELDS = [
    "catalogue", "index", "params", "trajectory_source", "lane_width", "t", "ego", "objects",
    "record", "summary", "series", "profiles", "profiles_error"]
TRACK_FIELDS = ["id", "length", "width", "x", "y", "psi", "v"]


def test_dashboard_view_4_is_typed_and_answers_as_before(client: Any, catalogue: str) -> None:
    from app.dashboard import views
    from app.dashboard.schemas import ScenarioView

    r = client.get(f"/dashboard/api/catalogues/{catalogue}/scenarios/3")
    body = r.json()
    assert list(body) == SCENARIO_VIEW_FIELDS
    assert ScenarioView.model_validate_json(r.text).model_dump_json() == r.text
    view = views.scenario(_ctx(client), catalogue, 3)
    assert isinstance(view, ScenarioView)
    assert view.model_dump_json() == r.text
    assert list(body["ego"]) == TRACK_FIELDS
    assert all(list(o) == TRACK_FIELDS for o in body["objects"]) and body["objects"]
    assert len(body["ego"]["x"]) == len(body["t"]) == len(body["objects"][0]["v"])
    # the stored record and parameters, as the scenario page gives them
    page = client.get(f"/catalogues/{catalogue}/scenarios?order_by=index&offset=3&limit=1")
    record = page.json()["scenarios"][0]
    assert body["index"] == record["index"] == 3
    assert body["record"] == record and body["params"] == record["params"]
    # the R157 driver's ego is the scripted ego's car: its size
    assert body["profiles"] is not None and body["profiles_error"] is None
    r157 = body["profiles"]["r157_ego"]
    assert (r157["length"], r157["width"]) == (body["ego"]["length"], body["ego"]["width"])
    assert isinstance(r157["length"], float) and r157["length"] > 0


#: POST /risk's fields in their order
RISK_REPORT_FIELDS = ["format", "settings", "surfaces", "summary", "evasion_bits", "series",
                      "objects", "criticality", "criticality_error"]


def test_risk_report_is_typed_and_answers_as_before(client: Any,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    import math
    from pathlib import Path

    from app.cli.main import main
    from app.schemas import RiskReport
    from app.services import risk

    example = json.loads(Path("examples/cut-in.json").read_text())
    r = client.post("/risk", json=example)
    body = r.json()
    assert list(body) == RISK_REPORT_FIELDS
    assert RiskReport.model_validate_json(r.text).model_dump_json() == r.text
    report = risk.score(example)
    assert isinstance(report, RiskReport)
    assert report.model_dump_json() == r.text
    # the CLI prints the same report
    assert main(["risk", "examples/cut-in.json"]) == 0
    assert capsys.readouterr().out == r.text + "\n"
    # values from the posted scenario and within the report
    n = len(example["t"])
    assert body["series"]["t"] == example["t"]
    assert all(len(v) == n for v in body["series"].values())
    assert [o["id"] for o in body["objects"]] == [o["id"] for o in example["objects"]]
    assert next(iter(body["summary"])) == "ego" and body["summary"]["ego"] == risk.SUMMARY_EGO
    assert body["summary"]["risk"] == max(body["series"]["r_dep"])
    # +inf: a float in the typed object, "Infinity" in the JSON (also inside the objects)
    ttr = report.objects[0]["series"]["min_ttr"]
    k = next(i for i, v in enumerate(ttr) if math.isinf(v))
    assert body["objects"][0]["series"]["min_ttr"][k] == "Infinity"
    assert body["criticality"] is not None and body["criticality_error"] is None


def test_model_comparison_is_typed_and_answers_as_before(client: Any) -> None:
    from app.dashboard import rates_views
    from app.rates import ModelComparison
    from datasets import PARAM_NAMES

    query = "a=default&b=default&n=30&constraints=gap<5&seed=2"
    r = client.get(f"/models/compare?{query}")
    assert r.status_code == 200, r.text
    body = r.json()
    assert list(body) == ["constraints", "n", "seed", "models", "parameters"]
    assert ModelComparison.model_validate_json(r.text).model_dump_json() == r.text
    view = rates_views.compare_models(_ctx(client), "default", "default", "gap<5", 30, 2)
    assert isinstance(view, ModelComparison)
    assert view.model_dump_json() == r.text
    assert (body["constraints"], body["n"], body["seed"]) == (["gap<5"], 30, 2)
    a, b = body["models"]
    assert list(a) == ["id", "dataset", "n_components", "features", "exposure", "p_region",
                       "rates"]
    assert a == b and a["id"] == _ctx(client).default_model_id  # the same model twice
    assert [p["name"] for p in body["parameters"]] == list(PARAM_NAMES)
    for p in body["parameters"]:
        assert len(p["models"]) == 2
        assert all(side["constrained"]["n"] == 30 for side in p["models"]), p["name"]


def test_region_report_is_typed_and_answers_as_before(client: Any) -> None:
    from app.rates import RegionReport
    from app.services import rates

    r = client.get("/dashboard/api/models/default/rates?constraints=gap<5&seed=2")
    assert r.status_code == 200, r.text
    body = r.json()
    assert list(body) == ["model", "constraints", "seed", "p_region", "rates", "exposure"]
    assert RegionReport.model_validate_json(r.text).model_dump_json() == r.text
    report = rates.region_rates(_ctx(client), "default", "gap<5", 2)
    assert isinstance(report, RegionReport)
    assert report.model_dump_json() == r.text
    # a rate is P(A) times the rate of all cut-ins (n_events / hours)
    exposure = body["exposure"]
    assert body["rates"]["exposure"] == exposure
    per_hour = body["p_region"]["estimate"] * exposure["n_events"] / exposure["hours"]
    assert body["rates"]["per_hour"]["estimate"] == pytest.approx(per_hour, rel=1e-12)


#: riskcore's built-in systems under test (docs/evaluation.md)
BUILTIN_SUTS = ["none", "r157_cc", "r157_cc_conflict", "rss", "idm", "acc", "acc_aeb",
                "ttr_aeb"]


def test_sut_info_is_typed_and_answers_as_before(client: Any,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli.main import main
    from app.schemas import SutInfo
    from app.services import suts

    r = client.get("/suts")
    body = r.json()
    assert list(body) == ["suts", "conflicts"]
    names = [s["name"] for s in body["suts"]]
    assert names[:len(BUILTIN_SUTS)] == BUILTIN_SUTS
    for item in body["suts"]:
        assert list(item) == ["name", "origin", "summary", "parameters", "source"]
        assert SutInfo.model_validate(item).model_dump(mode="json") == item
    listed = suts.list_suts()
    assert all(isinstance(s, SutInfo) for s in listed)
    assert [s.model_dump(mode="json") for s in listed] == body["suts"]
    assert all(s.origin == "builtin" for s in listed[:len(BUILTIN_SUTS)])
    # the CLI lists the same, one JSON document
    assert main(["evaluate", "--list-suts"]) == 0
    assert capsys.readouterr().out == json.dumps(body["suts"], indent=1) + "\n"


#: P(A)'s keys as the store holds them, in their order: the sampler's PRegion fields, ci,
#: then what the uncertainty report adds (the test model has replicates and an exposure)
STORED_P_REGION = ["estimate", "ci_low", "ci_high", "confidence", "method", "n_draws",
                   "n_hits", "p_bounds", "p_bounds_ci", "p_joint", "cov", "ci", "mc_ci",
                   "model_ci", "model_interval", "rates"]


def test_p_region_keeps_its_declared_shape_from_the_sampler_to_the_store(
        client: Any, catalogue: str) -> None:
    from pydantic import TypeAdapter

    from app import domain
    from app.db.models import CatalogueRow, ChunkRow
    from app.schemas import PRegion, PRegionJSON

    ctx = _ctx(client)
    declared = TypeAdapter(PRegionJSON)
    with ctx.db.read_session() as s:
        stored = s.get(CatalogueRow, catalogue).p_region
        chunks = s.query(ChunkRow).filter(ChunkRow.catalogue_id == catalogue).all()
        in_chunks = [c.diagnostics["p_region"] for c in chunks]
    # the catalogue's P(A): every key declared, of the declared type, in the declared order
    assert list(stored) == STORED_P_REGION
    assert declared.validate_python(stored, strict=True) == stored
    assert set(stored) <= set(PRegionJSON.__annotations__)
    # what a sample's result carries (POST /scenarios, the chunks) has the same shape
    model = ctx.model(ctx.default_model_id)
    drawn = domain.sample(model, domain.parse_constraints(["ttc<3"]), 20, 1)
    assert list(drawn.p_region) == STORED_P_REGION
    assert declared.validate_python(drawn.p_region, strict=True) == drawn.p_region
    for p in in_chunks:  # a chunk reuses the catalogue's P(A): its fields, no report
        assert list(p) == STORED_P_REGION[:12]
        assert declared.validate_python(p, strict=True) == p
    # and the response schema reads each of them
    for p in (stored, drawn.p_region, *in_chunks):
        read = PRegion.model_validate(p)
        assert read.estimate == p["estimate"] and read.ci == p["ci"]
