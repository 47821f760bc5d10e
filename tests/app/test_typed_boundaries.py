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
