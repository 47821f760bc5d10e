"""issue 12 over HTTP: a region's rates with both intervals (dashboard view 5) and two
models side by side (GET /models/compare)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest


@pytest.fixture(scope="module")
def other_model(client: Any) -> str:
    r = client.post("/models", json={"dataset": "tno-cutin", "options": {
        "k_range": [1, 1], "n_init": 1, "cv_folds": 2, "n_report_samples": 500,
        "n_bootstrap": 10}})
    assert r.status_code == 201, r.text
    model_id: str = r.json()["id"]
    return model_id


def test_region_rates_view(client: Any) -> None:
    r = client.get("/dashboard/api/models/default/rates", params={"constraints": "ttc<3"})
    assert r.status_code == 200, r.text
    body = r.json()
    p, rates = body["p_region"], body["rates"]
    lam = 208 / 63.0  # the embedded table's cut-ins over the source's hours
    assert rates["per_hour"]["estimate"] == pytest.approx(lam * p["estimate"], rel=1e-12)
    assert rates["per_hour"]["mc_ci"] == pytest.approx([lam * v for v in p["mc_ci"]],
                                                       rel=1e-12)
    mi = p["model_interval"]
    reps = np.asarray(mi["replicates"], dtype=float)
    # the model interval is the replicates' 2.5 / 97.5 % percentiles
    assert p["model_ci"] == pytest.approx(list(np.quantile(reps, [0.025, 0.975])), rel=1e-12)
    assert mi["n_boot"] == reps.size == 100 and mi["lower_resolved"]
    assert body["exposure"]["hours"] == 63.0
    bad = client.get("/dashboard/api/models/default/rates", params={"constraints": "ttc<<3"})
    assert bad.status_code == 422 and bad.json()["error"]["field"].startswith(
        "query.constraints")


@pytest.mark.slow
def test_compare_two_models(client: Any, other_model: str) -> None:
    r = client.get("/models/compare", params={"a": "default", "b": other_model,
                                              "constraints": "ttc<3", "n": 100})
    assert r.status_code == 200, r.text
    body = r.json()
    a, b = body["models"]
    assert b["id"] == other_model and a["n_components"] >= 1 and b["n_components"] == 1
    for side in (a, b):
        p = side["p_region"]
        assert 0 < p["estimate"] < 0.05 and p["model_ci"][0] < p["model_ci"][1]
        assert side["rates"]["per_hour"]["estimate"] == pytest.approx(
            208 / 63.0 * p["estimate"], rel=1e-12)
    assert [q["name"] for q in body["parameters"]] == ["p_y1", "p_t", "p_a1", "p_a2", "p_a3",
                                                       "p_v0", "dv", "gap"]
    gap = {q["name"]: q for q in body["parameters"]}["gap"]
    for hist in gap["models"]:
        # shared bins; the constrained histogram holds the n samples (all inside ttc<3)
        assert hist["unconstrained"]["edges"] == gap["models"][0]["constrained"]["edges"]
        assert hist["constrained"]["n"] == 100
    # same request, same answer (seeded)
    again = client.get("/models/compare", params={"a": "default", "b": other_model,
                                                  "constraints": "ttc<3", "n": 100}).json()
    assert again == body


@pytest.mark.parametrize(("params", "status", "field"), [
    ({"a": "nope", "b": "default"}, 404, "query.a"),
    ({"a": "default", "b": "nope"}, 404, "query.b"),
    ({"a": "default", "b": "default", "constraints": "ttc<<3"}, 422, "query.constraints.0"),
    ({"a": "default", "b": "default", "n": 0}, 422, "query.n"),
    ({"b": "default"}, 422, "query.a"),
])
def test_compare_errors_name_the_field(client: Any, params: dict[str, Any], status: int,
                                       field: str) -> None:
    r = client.get("/models/compare", params=params)
    assert r.status_code == status, r.text
    assert r.json()["error"]["field"] == field
