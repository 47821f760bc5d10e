"""Models: list (default first), show (components, BIC curve, fit report), fit."""

from __future__ import annotations

from typing import Any

import pytest


def test_list_and_show_the_default_model(client: Any) -> None:
    models = client.get("/models").json()["models"]
    assert models[0]["default"] is True and models[0]["dataset"] == "tno-cutin"
    for ref in (models[0]["id"], "default"):
        r = client.get(f"/models/{ref}")
        assert r.status_code == 200
        body = r.json()
        assert body["id"] == models[0]["id"]
        assert len(body["components"]) == body["n_components"] >= 1
        assert sum(c["weight"] for c in body["components"]) == pytest.approx(1.0)
        ks = [row["k"] for row in body["bic_curve"]]
        assert body["n_components"] in ks
        assert body["fit_report"]["n_rows"] > 0


def test_fit_a_model_with_options(client: Any) -> None:
    r = client.post("/models", json={"dataset": "tno-cutin",
                                     "options": {"k_range": [1, 2], "n_init": 1,
                                                 "n_report_samples": 500}})
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["n_components"] in (1, 2)
    assert [row["k"] for row in body["bic_curve"]] == [1, 2]
    assert client.get(f"/models/{body['id']}").json()["model_hash"] == body["model_hash"]
    assert body["id"] in [m["id"] for m in client.get("/models").json()["models"]]


@pytest.mark.parametrize(("body", "status", "field"), [
    ({"dataset": "nope"}, 404, "body.dataset"),
    ({"dataset": "tno-cutin", "options": {"no_such_option": 1}}, 422, "body.options"),
    ({"dataset": "tno-cutin", "options": {"k_range": [3, 1]}}, 422, "body.options.k_range"),
    ({"dataset": "tno-cutin", "extra": 1}, 422, "body.extra"),
    ({"dataset": 5}, 422, "body.dataset"),
])
def test_fit_errors(client: Any, body: dict[str, Any], status: int, field: str) -> None:
    r = client.post("/models", json=body)
    assert r.status_code == status, r.text
    assert r.json()["error"]["field"] == field


def test_unknown_model_is_404(client: Any) -> None:
    r = client.get("/models/nope")
    assert r.status_code == 404 and r.json()["error"]["field"] == "path.model_id"
