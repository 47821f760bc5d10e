"""Issue 14 items 16 and 17: the OpenAPI documents every status and media type the service
answers; error messages echo no server paths and no huge ids; an optional API key guards
the mutating endpoints; cross-site browser writes are refused."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.app.factories import copy_model_cache, make_app, make_settings

KEY = "s3cret-key-for-tests"


@pytest.fixture(scope="module")
def keyed(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    data_dir = tmp_path_factory.mktemp("keyed")
    copy_model_cache(model_cache_dir, data_dir)
    app = make_app(make_settings(data_dir, api_key=KEY))
    with TestClient(app) as client:
        yield client


# --------------------------------------------------------------------------- item 16
def test_openapi_documents_the_error_statuses_in_the_error_shape(client: Any) -> None:
    spec = client.get("/openapi.json").json()
    error = spec["components"]["schemas"]["Error"]
    assert error["required"] == ["error"]
    ops = {(p, m): op for p, item in spec["paths"].items() for m, op in item.items()}
    for (path, method), op in ops.items():
        codes = set(op["responses"])
        assert "422" in codes and "404" in codes, (path, method)
        if "requestBody" in op:
            assert {"400", "413"} <= codes, (path, method)
        if method != "get":
            assert {"401", "403"} <= codes, (path, method)
    body = ops[("/scenarios", "post")]["responses"]["413"]["content"]["application/json"]
    assert body["schema"] == {"$ref": "#/components/schemas/Error"}
    # the 422 is documented as the body it really is, not FastAPI's {"detail": [...]}
    assert "HTTPValidationError" not in spec["components"]["schemas"]


def test_openapi_documents_the_non_json_media_types(client: Any) -> None:
    spec = client.get("/openapi.json").json()

    def media(path: str) -> set[str]:
        return set(spec["paths"][path]["get"]["responses"]["200"]["content"])

    assert media("/catalogues/{catalogue_id}/export") == {
        "application/x-ndjson", "text/csv", "application/vnd.apache.parquet", "application/zip"}
    assert {"application/json", "text/csv"} <= media("/datasets/{dataset_id}/parameters")
    assert media("/dashboard") == {"text/html"}
    assert "text/javascript" in media("/dashboard/static/plotly.min.js")


def test_errors_echo_no_server_paths_and_no_huge_ids(client: Any) -> None:
    data_dir = str(client.app.state.ctx.data_dir)
    bad = client.post("/datasets", data={"kind": "egocentric"},
                      files=[("files", ("drives.csv", b"event_id,t\nx,0\n", "text/csv"))])
    assert bad.status_code == 422
    assert data_dir not in bad.text and "/tmp/" not in bad.text, bad.text
    huge = "m" * 1_000_000
    r = client.post("/scenarios", json={"model": huge, "n": 1})
    assert r.status_code == 404
    assert len(r.text) < 3000 and huge[:200] not in r.text


def test_a_405_lists_every_method_of_the_path(client: Any) -> None:
    r = client.request("PUT", "/catalogues")
    assert r.status_code == 405
    assert set(r.headers["allow"].replace(" ", "").split(",")) == {"GET", "POST"}


# --------------------------------------------------------------------------- item 17
def test_with_a_key_writes_need_it_and_reads_do_not(keyed: Any) -> None:
    assert keyed.get("/catalogues").status_code == 200
    body = {"n": 1, "seed": 1, "score": False}
    r = keyed.post("/scenarios", json=body)
    assert r.status_code == 401 and r.json()["error"]["field"] == "header.x-api-key"
    assert keyed.post("/scenarios", json=body,
                      headers={"X-API-Key": "wrong"}).status_code == 401
    assert keyed.post("/scenarios", json=body, headers={"X-API-Key": KEY}).status_code == 200
    assert keyed.post("/scenarios", json=body,
                      headers={"Authorization": f"Bearer {KEY}"}).status_code == 200
    assert keyed.delete("/catalogues/cat-nope").status_code == 401


def test_without_a_key_writes_are_open(client: Any) -> None:
    r = client.post("/scenarios", json={"n": 1, "seed": 1, "score": False})
    assert r.status_code == 200


def test_cross_site_form_uploads_are_refused(client: Any) -> None:
    before = client.get("/datasets").json()["datasets"]
    form = {"data": {"kind": "egocentric"},
            "files": [("files", ("x.csv", b"event_id\n", "text/csv"))]}
    r = client.post("/datasets", headers={"Origin": "https://evil.example"}, **form)
    assert r.status_code == 403 and r.json()["error"]["field"] == "header.origin"
    r = client.post("/datasets", headers={"Sec-Fetch-Site": "cross-site"}, **form)
    assert r.status_code == 403
    r = client.post("/scenarios", json={"n": 1}, headers={"Origin": "null"})
    assert r.status_code == 403
    assert client.get("/datasets").json()["datasets"] == before
    # the service's own pages (same origin) may write
    same = client.post("/scenarios", json={"n": 1, "seed": 1, "score": False},
                       headers={"Origin": "http://testserver", "Sec-Fetch-Site": "same-origin"})
    assert same.status_code == 200
