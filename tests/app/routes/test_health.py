"""GET /health, GET /version, the OpenAPI docs."""

from __future__ import annotations

from typing import Any

from app import __version__


def test_health_reports_the_store_and_the_default_model(client: Any) -> None:
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok"
    assert body["database"] == "sqlite"
    assert body["default_model"].startswith("default-")
    assert body["default_dataset"] == "tno-cutin"
    assert body["startup_error"] is None


def test_version(client: Any) -> None:
    r = client.get("/version")
    assert r.status_code == 200
    assert r.json()["versions"]["scengen"] == __version__


def test_openapi_docs_list_every_resource(client: Any) -> None:
    assert client.get("/docs").status_code == 200
    paths = set(client.get("/openapi.json").json()["paths"])
    assert {"/health", "/version", "/datasets", "/datasets/{dataset_id}",
            "/datasets/{dataset_id}/parameters", "/models", "/models/{model_id}",
            "/scenarios", "/risk", "/catalogues", "/catalogues/{catalogue_id}",
            "/catalogues/{catalogue_id}/scenarios",
            "/catalogues/{catalogue_id}/export"} <= paths


def test_unknown_path_and_method_use_the_error_shape(client: Any) -> None:
    r = client.get("/no/such/thing")
    assert r.status_code == 404 and r.json()["error"]["status"] == 404
    r = client.put("/health")
    assert r.status_code == 405 and r.json()["error"]["status"] == 405


def test_health_says_warming_while_the_start_up_warm_up_runs(client: Any) -> None:
    """Issue 25 item 4: a first scored request sent while /health says "ok" must not wait
    for kernels or estimates; while they load, /health says "warming"."""
    import threading

    ctx = client.app.state.ctx
    release = threading.Event()
    thread = threading.Thread(target=release.wait, daemon=True)
    before = ctx._warm_thread
    ctx._warm_thread = thread
    try:
        thread.start()
        assert client.get("/health").json()["status"] == "warming"
        release.set()
        thread.join(timeout=10)
        assert client.get("/health").json()["status"] == "ok"
    finally:
        release.set()
        ctx._warm_thread = before
