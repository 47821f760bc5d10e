"""The dashboard's section 7 (a system under test) in headless Chromium: two evaluations
made with the real simulator (the SUT ``acc`` and the careful driver ``r157_cc``) are
shown; the table holds both rates, the failures list and the scatter hold what the view's
JSON says, and clicking a failing run drives it again. Screenshot:
``test-artifacts/dashboard/sut.png``."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import sync_playwright

from tests.app.factories import make_settings, uvicorn_service
from tests.browser.factories import CHROMIUM, CHROMIUM_ARGS, prepare_data_dir

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts" / "dashboard"
TIMEOUT_MS = 180_000


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, str]]]:
    from app.services import evaluations as service
    from app.services.store import open_context

    data_dir = prepare_data_dir(tmp_path_factory.mktemp("sut-browser"))
    ctx = open_context(make_settings(data_dir))
    ids = {}
    try:
        for sut in ("r157_cc", "acc"):
            row = service.create(ctx, sut=sut, n=400, seed=1, batch_size=200)
            assert service.run_job(ctx, row.id) == "done"
            ids[sut] = row.id
    finally:
        ctx.close()
    env = dict(os.environ, SCENGEN_DATA_DIR=str(data_dir), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_RESUME_JOBS="false", SCENGEN_WARM_START="0")
    for name in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        env.pop(name, None)
    with uvicorn_service(env, data_dir / "uvicorn.log") as base:
        yield base, ids


def test_the_system_under_test_section(served: tuple[str, dict[str, str]]) -> None:
    base, ids = served
    view = httpx.get(f"{base}/dashboard/api/evaluations/{ids['acc']}", timeout=120).json()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 1000})
            errors: list[str] = []
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            outside: list[str] = []
            page.on("request", lambda r: outside.append(r.url)
                    if not r.url.startswith(base) and not r.url.startswith("data:") else None)
            page.goto(f"{base}/dashboard#view-sut")
            page.wait_for_selector("#sut-note[data-state=done]", timeout=TIMEOUT_MS)
            # the newest finished evaluation of a SUT other than the careful driver
            assert page.locator("#eval-select").input_value() == ids["acc"]
            table = page.locator("#sut-table").inner_text()
            assert "acc · collisions per hour" in table
            assert "r157_cc (careful driver) · collisions per hour" in table
            assert "no finished evaluation" not in table
            page.wait_for_selector("#sut-scatter[data-rendered='1']", timeout=TIMEOUT_MS)
            points = page.locator("#sut-scatter .scatterlayer .point").count()
            sc = view["scatter"]
            y = sc["impact_speed"] if sc["note"] else sc["r_dep_peak"]
            shown = sum(1 for b, r in zip(sc["btn"], y, strict=True)
                        if b is not None and r is not None)
            assert shown > 0
            assert points == shown
            rows = page.locator("#sut-failures tr[data-run]")
            assert rows.count() == len(view["failures"])
            # an evaluation without `risk` has no r_dep: the table says so, not "NaN"
            assert "NaN" not in page.locator("#sut-failures").inner_text()
            if view["failures"]:
                page.wait_for_selector("#sut-run-plot[data-rendered='1']", timeout=TIMEOUT_MS)
                first = view["failures"][0]["run"]
                assert page.locator("#sut-run-plot").get_attribute(
                    "data-source") == f"{ids['acc']}#{first}"
                if len(view["failures"]) > 1:
                    second = view["failures"][1]["run"]
                    rows.nth(1).click()
                    page.wait_for_selector(
                        f"#sut-run-plot[data-source='{ids['acc']}#{second}']",
                        timeout=TIMEOUT_MS)
                    assert f"Run {second}:" in page.locator("#sut-run-info").inner_text()
                # speed and acceleration of both drivers at least
                assert page.locator("#sut-run-plot .scatterlayer .trace").count() >= 4
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.locator("#view-sut").screenshot(path=str(ARTIFACTS / "sut.png"))
            assert errors == []
            assert outside == []
        finally:
            browser.close()
