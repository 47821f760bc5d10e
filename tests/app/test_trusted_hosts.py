"""Host validation (issue 27 item 4): the service answers only to the host names it is
told to trust (loopback by default), so DNS rebinding — a page of evil.example whose name
is made to resolve to 127.0.0.1, talking to the service "same-origin" — gets 400."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.guards import host_allowed, host_name, trusted_host_names
from app.settings import Settings
from tests.app.factories import copy_model_cache, make_app, make_settings

PORT = 8000


@pytest.fixture(scope="module")
def loopback(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """A service with the default trusted hosts (the loopback names only)."""
    from fastapi.testclient import TestClient

    data_dir = tmp_path_factory.mktemp("hosts")
    copy_model_cache(model_cache_dir, data_dir)
    settings = make_settings(data_dir)
    settings = settings.model_copy(update={"trusted_hosts": Settings().trusted_hosts})
    with TestClient(make_app(settings), base_url=f"http://127.0.0.1:{PORT}") as client:
        yield client


def test_dns_rebinding_is_refused_on_reads_and_writes(loopback: Any) -> None:
    evil = {"host": f"evil.example:{PORT}", "origin": f"http://evil.example:{PORT}"}
    # before the fix: the POST with a matching Origin passed the cross-site guard (200)
    r = loopback.post("/scenarios", json={"n": 1, "score": False}, headers=evil)
    assert r.status_code == 400, r.text
    assert r.json()["error"]["field"] == "header.host"
    assert "evil.example" in r.json()["error"]["message"]
    assert "SCENGEN_TRUSTED_HOSTS" in r.json()["error"]["message"]
    # reads too: a rebinding page must not read the catalogues either
    assert loopback.get("/catalogues", headers={"host": "evil.example"}).status_code == 400
    assert loopback.get("/health", headers={"host": "localhost.evil.example"}).status_code == 400


@pytest.mark.parametrize("host", [f"127.0.0.1:{PORT}", f"localhost:{PORT}", "localhost",
                                  f"[::1]:{PORT}", "LOCALHOST:8000"])
def test_the_loopback_names_are_answered(loopback: Any, host: str) -> None:
    r = loopback.get("/catalogues", headers={"host": host})
    assert r.status_code == 200, (host, r.text)


def test_a_same_origin_write_on_loopback_still_works(loopback: Any) -> None:
    r = loopback.post("/scenarios", json={"n": 1, "score": False},
                      headers={"origin": f"http://127.0.0.1:{PORT}"})
    assert r.status_code == 200, r.text


@pytest.mark.parametrize(("header", "name"), [
    ("example.org", "example.org"), ("Example.ORG:8443", "example.org"),
    ("[::1]:8000", "::1"), ("[::1]", "::1"), ("127.0.0.1:80", "127.0.0.1"),
    ("host.example.", "host.example")])
def test_host_name_drops_the_port_and_case(header: str, name: str) -> None:
    assert host_name(header) == name


def test_trusted_names_patterns_and_the_bind_address() -> None:
    default = Settings(trusted_hosts=["localhost", "127.0.0.1", "::1"])
    assert trusted_host_names(default) == ["localhost", "127.0.0.1", "::1"]
    # a service bound to a specific name answers to it; 0.0.0.0 names nothing
    assert "scengen.lab" in trusted_host_names(Settings(host="scengen.lab"))
    assert trusted_host_names(Settings(host="0.0.0.0")) == list(Settings().trusted_hosts)
    subs = ["*.lab.example"]
    assert host_allowed("a.lab.example:8000", subs)
    assert not host_allowed("lab.example", subs)  # the pattern is for subdomains
    assert not host_allowed("evil-lab.example", subs)
    assert host_allowed("anything.example", ["*"])
    assert not host_allowed(None, ["localhost"]) and not host_allowed("", ["localhost"])


def test_trusted_hosts_come_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SCENGEN_TRUSTED_HOSTS", '["scengen.lab.example", "localhost"]')
    assert Settings().trusted_hosts == ["scengen.lab.example", "localhost"]
    monkeypatch.delenv("SCENGEN_TRUSTED_HOSTS")
    assert Settings().trusted_hosts == ["localhost", "127.0.0.1", "::1"]
