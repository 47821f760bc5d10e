"""The dashboard with an API key set (issue 27 follow-up): the costly reads behind views 1,
2 and 5 (fit, shift, rates) need the key, so the page asks for it in a header field, keeps
it in sessionStorage and sends it as X-API-Key on every request; a 401 says where to
enter it. The export links download through the same fetch (with the key), not as plain
links, which cannot send a header. Headless Chromium against the service started here (quick
default model)."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import BrowserContext, Page, Request

from tests.app.factories import uvicorn_service
from tests.browser.dashboard import Server, settle
from tests.browser.factories import prepare_data_dir, synthetic_rows

pytestmark = pytest.mark.browser

KEY = "k3y-for-the-dashboard"


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path]]:
    data_dir = prepare_data_dir(tmp_path_factory.mktemp("key-data"))
    env = dict(os.environ, SCENGEN_DATA_DIR=str(data_dir), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_WARM_START="0", SCENGEN_API_KEY=KEY)
    for name in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        env.pop(name, None)
    with uvicorn_service(env, data_dir / "uvicorn.log") as url:
        yield url, data_dir


@pytest.fixture(scope="module")
def base(served: tuple[str, Path]) -> str:
    return served[0]


N_ROWS = 7


@pytest.fixture(scope="module")
def catalogue(served: tuple[str, Path]) -> str:
    """A finished catalogue of N_ROWS hand-made rows (seed 3) in the service's store."""
    return Server(*served).catalogue(n=N_ROWS, seed=3)


@pytest.fixture
def page(context: BrowserContext) -> Iterator[Page]:
    yield context.new_page()


def test_the_dashboard_asks_for_the_key_once_and_sends_it_on_every_request(
        base: str, page: Page) -> None:
    sent: list[tuple[str, str | None]] = []

    def record(request: Request) -> None:
        if "/dashboard/api/" in request.url or "/models" in request.url:
            sent.append((request.url, request.headers.get("x-api-key")))

    page.on("request", record)
    page.goto(f"{base}/dashboard")
    settle(page)
    # without the key: the fit view's read is refused, and the message says where to
    # enter the key (before: no field, and a message naming only a header)
    error = page.locator("#error").inner_text()
    assert "401" in error and 'in the header\'s "API key" field' in error
    assert page.locator("#key-form").get_attribute("data-needed") == "1"
    assert page.locator("#fit-grid .plot[data-rendered='1']").count() == 0

    page.fill("#api-key-input", KEY)
    sent.clear()
    with page.expect_navigation():
        page.press("#api-key-input", "Enter")
    settle(page)
    assert page.locator("#error").is_hidden()
    page.wait_for_selector("#fit-grid .plot[data-rendered='1']")
    assert sent and all(key == KEY for _, key in sent)
    assert page.evaluate("sessionStorage.getItem('scengen-api-key')") == KEY
    assert page.input_value("#api-key-input") == KEY  # kept for the tab


def test_a_wrong_key_is_named_as_wrong(base: str, page: Page) -> None:
    page.goto(f"{base}/dashboard")
    page.evaluate("sessionStorage.setItem('scengen-api-key', 'not-the-key')")
    page.reload()
    settle(page)
    error = page.locator("#error").inner_text()
    assert "refused the API key entered" in error and "401" in error


def export_link(page: Page, fmt: str) -> str:
    link = page.locator("#catalogue-info a", has_text=fmt)
    link.wait_for()
    return link.get_attribute("href") or ""


def test_an_export_link_downloads_with_the_key(base: str, catalogue: str, page: Page,
                                               tmp_path: Path) -> None:
    page.goto(f"{base}/dashboard/catalogues/{catalogue}")
    page.evaluate(f"sessionStorage.setItem('scengen-api-key', {KEY!r})")
    page.reload()
    settle(page)
    href = export_link(page, "jsonl")
    assert href == f"/catalogues/{catalogue}/export?format=jsonl"
    assert httpx.get(base + href).status_code == 401  # the plain link would be refused
    with page.expect_download() as info:
        page.locator("#catalogue-info a", has_text="jsonl").click()
    download = info.value
    assert download.failure() is None
    assert download.suggested_filename == f"{catalogue}.jsonl"  # Content-Disposition
    saved = tmp_path / "saved.jsonl"
    download.save_as(saved)
    content = saved.read_bytes()
    # the export itself, byte for byte, and the rows stored above (hand-made, seed 3)
    assert content == httpx.get(base + href, headers={"X-API-Key": KEY}).content
    records = [json.loads(line) for line in content.decode().splitlines()]
    expected = synthetic_rows(N_ROWS, 3, 1000)
    assert records[0]["kind"] == "manifest" and records[0]["manifest"]["seed"] == 3
    assert [r["kind"] for r in records[1:]] == ["scenario"] * N_ROWS
    assert [r["index"] for r in records[1:]] == list(range(N_ROWS))
    assert [r["summary"]["risk"] for r in records[1:]] == [
        row["summary"]["risk"] for row in expected]
    assert page.locator("#error").is_hidden()


def test_an_export_link_without_the_key_says_where_to_enter_it(
        base: str, catalogue: str, page: Page) -> None:
    page.goto(f"{base}/dashboard/catalogues/{catalogue}")
    settle(page)
    downloads: list[object] = []
    page.on("download", lambda d: downloads.append(d))
    page.locator("#catalogue-info a", has_text="csv").click()
    page.wait_for_function(
        "document.getElementById('error').innerText.includes('export ')")
    error = page.locator("#error").inner_text()
    line = next(x for x in error.splitlines() if x.startswith("export "))
    assert line.startswith(f"export {catalogue}.csv: this service needs its API key")
    assert 'in the header\'s "API key" field' in line and "(HTTP 401)" in line
    assert page.locator("#key-form").get_attribute("data-needed") == "1"
    assert downloads == []
