"""Auth where it costs (issue 27 item 4, finding 2): with an API key set, the reads that
sample, estimate or build files (compare, shift, rates, the model fit view, exports) need
it like the writes (before: 200 without it); reads of what is stored stay open, and
without a key everything is open as before."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.guards import costly_read
from tests.app.factories import copy_model_cache, make_app, make_settings

KEY = "another-s3cret-for-tests"
# with the key, each of these fails fast (a 422 or 404 after the key check: the key let
# it through) instead of doing the work
COSTLY = ["/models/compare?a=default&b=default&n=0",
          "/dashboard/api/models/default/shift?n=0",
          "/dashboard/api/models/default/rates?seed=-1",
          "/dashboard/api/models/nope/fit",
          "/dashboard/api/catalogues/cat-nope/shift",
          "/catalogues/cat-nope/export?format=csv",
          "/evaluations/eval-nope/export"]
OPEN = ["/health", "/version", "/catalogues", "/models", "/models/default",
        "/openapi.json", "/dashboard", "/catalogues/cat-nope/scenarios"]


@pytest.fixture(scope="module")
def keyed(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    data_dir = tmp_path_factory.mktemp("keyed-reads")
    copy_model_cache(model_cache_dir, data_dir)
    with TestClient(make_app(make_settings(data_dir, api_key=KEY))) as client:
        yield client


@pytest.mark.parametrize("path", COSTLY)
def test_a_costly_read_needs_the_key(keyed: Any, path: str) -> None:
    r = keyed.get(path)
    assert r.status_code == 401, r.text[:200]
    assert r.json()["error"]["field"] == "header.x-api-key"
    with_key = keyed.get(path, headers={"X-API-Key": KEY})
    assert with_key.status_code in (404, 422), with_key.text[:200]  # past the key check


@pytest.mark.parametrize("path", OPEN)
def test_a_cheap_read_stays_open(keyed: Any, path: str) -> None:
    assert keyed.get(path).status_code != 401


def test_without_a_key_costly_reads_are_open(client: Any) -> None:
    assert client.get("/dashboard/api/models/default/shift?n=0").status_code == 422


def test_which_paths_are_costly_reads() -> None:
    assert costly_read("GET", "/models/compare") and costly_read("GET", "/models/compare/")
    assert costly_read("HEAD", "/catalogues/c1/export")
    assert not costly_read("GET", "/models/default") and not costly_read("GET", "/catalogues")
    assert not costly_read("POST", "/models/compare")  # a write: the key's rule for writes
    assert not costly_read("GET", "/catalogues/c1/export/extra")
