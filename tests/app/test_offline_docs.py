"""Issue 14 item 1: /docs and /redoc need no network; `GET /` leads somewhere useful."""

from __future__ import annotations

import re
from typing import Any

import pytest


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_load_only_local_assets(client: Any, page: str) -> None:
    r = client.get(page)
    assert r.status_code == 200
    refs = re.findall(r"""(?:src|href)\s*=\s*['"]([^'"]+)['"]""", r.text)
    refs += re.findall(r"""url:\s*['"]([^'"]+)['"]""", r.text)
    assert refs, r.text
    for ref in refs:
        assert ref.startswith("/"), f"{page} loads {ref} from elsewhere"
        if ref != "/openapi.json":
            asset = client.get(ref)
            assert asset.status_code == 200 and len(asset.content) > 1000, ref
    assert "fonts.googleapis" not in r.text and "cdn" not in r.text.lower()


def test_root_links_to_the_docs_and_the_dashboard(client: Any) -> None:
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    links = set(re.findall(r'href="(/[^"]*)"', r.text))
    assert {"/docs", "/redoc", "/dashboard", "/openapi.json"} <= links
    for link in links:
        assert client.get(link).status_code == 200, link


def test_unknown_asset_is_404_in_the_error_shape(client: Any) -> None:
    r = client.get("/docs-static/..%2Fcore.py")
    assert r.status_code == 404
    assert r.json()["error"]["status"] == 404


def test_the_redoc_bundle_asks_no_cdn_for_its_logo(client: Any) -> None:
    """Issue 25: /redoc's page fetched https://cdn.redoc.ly/redoc/logo-mini.svg (seen in
    Chromium); the served bundle names no outside address and its logo is local."""
    js = client.get("/docs-static/redoc.standalone.js")
    assert js.status_code == 200 and len(js.content) > 100_000
    assert re.findall(rb"https?://cdn[\w./-]*", js.content) == []
    assert b"/docs-static/redoc-logo.svg" in js.content
    logo = client.get("/docs-static/redoc-logo.svg")
    assert logo.status_code == 200 and logo.headers["content-type"] == "image/svg+xml"
    assert logo.content.startswith(b"<svg")
