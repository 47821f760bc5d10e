"""What the dashboard's browser tests share (test_dashboard_browser.py,
test_dashboard_usability.py, test_dashboard_api_key.py): the service started here with
uvicorn on a private data dir and SQLite database (quick default model), waiting for the
page's own ready signal, and whole-element screenshots under ``test-artifacts/dashboard/``.
The browser and a fresh context per test are fixtures (tests/browser/conftest.py).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
from playwright.sync_api import Page, ViewportSize

from app.db.database import Database
from tests.app.factories import uvicorn_service
from tests.browser.factories import store_synthetic_catalogue

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts" / "dashboard"
#: how long a page action or wait may take, ms
TIMEOUT_MS = 120_000
VIEWPORT: ViewportSize = {"width": 1400, "height": 1000}


class Server:
    """The service: its base URL and data dir."""

    def __init__(self, base: str, data_dir: Path) -> None:
        self.base = base
        self.data_dir = data_dir

    def db(self) -> Database:
        return Database(f"sqlite:///{(self.data_dir / 'scengen.db').resolve()}")

    def default_model(self) -> str:
        model: str = httpx.get(f"{self.base}/health").json()["default_model"]
        return model

    def catalogue(self, rows: list[dict[str, Any]] | None = None, n: int = 60,
                  seed: int = 3, **kw: Any) -> str:
        """A finished synthetic catalogue of the default model in the service's store."""
        db = self.db()
        try:
            return store_synthetic_catalogue(db, self.data_dir, self.default_model(), n,
                                             seed=seed, rows=rows, **kw)
        finally:
            db.dispose()


@contextmanager
def dashboard_service(data_dir: Path, **env_extra: str) -> Iterator[Server]:
    """uvicorn on ``data_dir`` (prepared with ``prepare_data_dir``): no local workers,
    chunks of 6, its SQLite database, no Dask; ``env_extra`` on top."""
    env = dict(os.environ, SCENGEN_DATA_DIR=str(data_dir), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_CHUNK_SIZE="6", **env_extra)
    for name in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        env.pop(name, None)
    with uvicorn_service(env, data_dir / "uvicorn.log") as base:
        yield Server(base, data_dir)


def settle(page: Page) -> None:
    """Until the page is drawn and no request of its own is running."""
    page.wait_for_selector("body[data-ready='1']")
    page.wait_for_function("document.body.dataset.busy === '0'")


def shot(page: Page, selector: str, name: str) -> None:
    """Screenshot of one element, whole: the viewport is made tall enough for it and the
    sticky header is let go so it cannot cover the element."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.add_style_tag(content="header { position: static !important; }")
    size = page.viewport_size or VIEWPORT
    box = page.locator(selector).bounding_box()
    tall = int(box["height"]) + 200 if box else size["height"]
    page.set_viewport_size({"width": size["width"], "height": max(size["height"], tall)})
    try:
        page.locator(selector).screenshot(path=str(ARTIFACTS / name), animations="disabled")
    finally:
        page.set_viewport_size(size)
