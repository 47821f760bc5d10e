"""The dashboard with an API key set (issue 27 follow-up): the costly reads behind views 1,
2 and 5 (fit, shift, rates) need the key, so the page asks for it in a header field, keeps
it in sessionStorage and sends it as X-API-Key on every request; a 401 says where to
enter it. Headless Chromium against the service started here (quick default model)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from playwright.sync_api import Page, Request, sync_playwright

from tests.app.factories import uvicorn_service
from tests.browser.factories import CHROMIUM, CHROMIUM_ARGS, prepare_data_dir

pytestmark = pytest.mark.browser

KEY = "k3y-for-the-dashboard"
TIMEOUT_MS = 120_000


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data_dir = prepare_data_dir(tmp_path_factory.mktemp("key-data"))
    env = dict(os.environ, SCENGEN_DATA_DIR=str(data_dir), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_WARM_START="0", SCENGEN_API_KEY=KEY)
    for name in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        env.pop(name, None)
    with uvicorn_service(env, data_dir / "uvicorn.log") as url:
        yield url


@pytest.fixture
def page() -> Iterator[Page]:
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            context = browser.new_context(viewport={"width": 1400, "height": 1000})
            context.set_default_timeout(TIMEOUT_MS)
            yield context.new_page()
        finally:
            browser.close()


def settle(page: Page) -> None:
    page.wait_for_selector("body[data-ready='1']")
    page.wait_for_function("document.body.dataset.busy === '0'")


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
