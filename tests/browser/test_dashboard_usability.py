"""What a new user met in the dashboard (issue 25 item 6), in headless Chromium against the
service started here (quick default model, private data dir): header links that reloaded
the whole page, view 4 without the R157 driver's car, view 5 titled with the typed
constraint instead of the catalogue's, the riskiest-10 table, the histograms, a lone
unpreventable case, the running catalogue's progress text, the data support.

Each test looks at the page as drawn (Plotly's data, the DOM) and saves a screenshot under
``test-artifacts/dashboard/``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from playwright.sync_api import BrowserContext, Page

from tests.browser.dashboard import Server, dashboard_service, settle, shot
from tests.browser.factories import prepare_data_dir

pytestmark = pytest.mark.browser

@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    with dashboard_service(prepare_data_dir(tmp_path_factory.mktemp("usability-data")),
                           SCENGEN_WARM_START="0") as s:
        yield s


@pytest.fixture(scope="module")
def real_catalogue(server: Server) -> str:
    """A small scored catalogue made by the service (trajectories stored)."""
    r = httpx.post(f"{server.base}/catalogues", timeout=60,
                   json={"n": 12, "seed": 5, "constraints": ["ttc<2"]})
    assert r.status_code == 202, r.text
    cid: str = r.json()["id"]
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        status = httpx.get(f"{server.base}/catalogues/{cid}").json()["status"]
        if status not in ("queued", "running"):
            assert status == "done"
            return cid
        time.sleep(0.2)
    raise AssertionError("the catalogue did not finish")


@pytest.fixture
def page(context: BrowserContext) -> Iterator[Page]:
    pg = context.new_page()
    errors: list[str] = []
    pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    pg.on("pageerror", lambda exc: errors.append(f"pageerror: {exc}"))
    yield pg
    pg.close()
    assert errors == []


def traces(page: Page, div: str) -> list[dict[str, Any]]:
    data: list[dict[str, Any]] = page.evaluate(
        "(id) => Array.from(document.getElementById(id).data || [])"
        ".map((t) => ({x: t.x, y: t.y, name: t.name, width: t.width, type: t.type}))", div)
    return data


# --------------------------------------------------------------------------- navigation
def test_header_links_move_within_the_page_without_loading_it_again(
        server: Server, page: Page) -> None:
    """Every header link used to reload the whole page (5-12 s): the page's popstate
    handler reloaded on any history entry, and a #fragment link makes one."""
    first, second = server.catalogue(seed=11), server.catalogue(seed=12)
    page.goto(f"{server.base}/dashboard/catalogues/{first}")
    settle(page)
    page.evaluate("() => { window.__loadedOnce = true; }")
    for link in page.locator("header nav a[href^='#']").all():
        target = link.get_attribute("href")
        link.click()
        page.wait_for_function(f"window.location.hash === '{target}'")
        assert page.evaluate("() => window.__loadedOnce === true"), f"{target} reloaded"
    # the catalogue picker and Back switch catalogues here too, without a reload
    page.select_option("#catalogue-select", second)
    page.wait_for_selector(f"#class-counts[data-source='{second}']")
    settle(page)
    assert page.url.endswith(f"/dashboard/catalogues/{second}")
    page.go_back()  # the fragments, then the first catalogue
    while not page.url.split("#")[0].endswith(first):
        page.go_back()
    page.wait_for_selector(f"#class-counts[data-source='{first}']")
    settle(page)
    assert page.locator("#catalogue-select").input_value() == first
    assert page.evaluate("() => window.__loadedOnce === true"), "Back reloaded the page"


def test_a_malformed_or_unknown_fragment_still_loads_the_page(server: Server,
                                                             page: Page) -> None:
    """The page reads its #fragment to stay on a linked view; a fragment that is not
    valid percent-encoding (``#%E0``) or names no view must not stop it from loading
    (``page`` fails on any console error or uncaught exception)."""
    for frag in ("%E0", "no-such-view"):
        page.goto(f"{server.base}/dashboard#{frag}")
        page.wait_for_selector("body[data-ready='1']", timeout=180_000)


# --------------------------------------------------------------------------- view 4
def test_view4_draws_the_r157_drivers_car(server: Server, real_catalogue: str,
                                          page: Page) -> None:
    page.goto(f"{server.base}/dashboard/catalogues/{real_catalogue}?scenario=0")
    settle(page)
    page.wait_for_selector(f"#series-plot[data-source='{real_catalogue}#0']")
    drawn = {t["name"]: t for t in traces(page, "topdown-plot")}
    ego, r157 = drawn["ego (scripted)"], drawn["ego (R157 driver)"]
    for car in (ego, r157):
        assert all(isinstance(v, float | int) and math.isfinite(v) for v in car["x"]), car
    # the same car: its box as long and as wide as the scripted ego's
    assert max(r157["x"]) - min(r157["x"]) == pytest.approx(max(ego["x"]) - min(ego["x"]),
                                                           rel=0.2)
    assert max(r157["x"]) - min(r157["x"]) > 3.0
    shot(page, "#view-scenario", "ux-4-scenario-r157-car.png")


# --------------------------------------------------------------------------- view 5
def test_view5_shows_the_selected_catalogues_region(server: Server, real_catalogue: str,
                                                    page: Page) -> None:
    """A ttc<2 catalogue was plotted under the title "ttc<3" (the typed constraint)."""
    page.goto(f"{server.base}/dashboard/catalogues/{real_catalogue}")
    settle(page)
    assert page.locator("#constraint-input").input_value() == "ttc<3"  # the default
    page.wait_for_selector("#rates-note[data-state='done']")
    table = page.locator("#rates-table").inner_text()
    assert "Region ttc<2 under model" in table, table
    assert "ttc<3" not in table
    title = page.evaluate("() => document.getElementById('rates-bars').layout.title.text")
    assert "ttc<2" in title and "ttc<3" not in title, title
    assert f"catalogue {real_catalogue}'s" in page.locator("#rates-note").inner_text()
    shot(page, "#view-rates", "ux-5-rates-of-the-catalogue.png")
    # no catalogue: the typed constraint again
    page.select_option("#catalogue-select", "")
    page.wait_for_function("document.querySelector('#rates-table').innerText"
                           ".includes('Region ttc<3 under model')")


# --------------------------------------------------------------------------- view 3 table
def _table_indices(page: Page) -> list[int]:
    rows = page.locator("#top-table tr[data-index]")
    return [int(rows.nth(i).get_attribute("data-index") or -1) for i in range(rows.count())]


def test_the_riskiest_table_sorts_filters_and_fits(server: Server, real_catalogue: str,
                                                   page: Page) -> None:
    """The riskiest-10 table could not be sorted or filtered and its last column was cut at
    1400 px; it now sorts by a header click and filters by class and data support, on the
    whole catalogue (the API's order and filters), and shows each row's support."""
    base, cid = server.base, real_catalogue
    page.goto(f"{base}/dashboard/catalogues/{cid}")
    settle(page)
    url = f"{base}/catalogues/{cid}/scenarios"
    by_btn = httpx.get(url, params={"limit": 10}).json()["scenarios"]
    assert _table_indices(page) == [s["index"] for s in by_btn]
    cells = page.locator("#top-table tr[data-index]").first.locator("td")
    assert cells.nth(6).inner_text() == by_btn[0]["support"]
    # the whole table is inside its panel: nothing cut at 1400 px
    panel = page.locator("#top-table").bounding_box()
    table = page.locator("#top-table table").bounding_box()
    assert panel and table and table["x"] + table["width"] <= panel["x"] + panel["width"] + 1
    # sort by TTC (lowest first), then highest first
    page.locator("#top-table th[data-order='ttc']").click()
    page.wait_for_selector("#top-table[data-order='ttc asc']")
    want = httpx.get(url, params={"limit": 10, "order_by": "ttc", "desc": "false"}).json()
    assert _table_indices(page) == [s["index"] for s in want["scenarios"]]
    page.locator("#top-table th[data-order='ttc']").click()
    page.wait_for_selector("#top-table[data-order='ttc desc']")
    want = httpx.get(url, params={"limit": 10, "order_by": "ttc", "desc": "true"}).json()
    assert _table_indices(page) == [s["index"] for s in want["scenarios"]]
    # filter by data support: what the real cut-ins support
    status = httpx.get(f"{base}/catalogues/{cid}").json()
    page.select_option("#top-support", "inside,near")
    supported = status["support"]["inside"] + status["support"]["near"]
    page.wait_for_function(
        f"document.querySelector('#top-table h3').innerText.includes('of {supported} matching')")
    shown = [c.inner_text() for c in page.locator("#top-table tr[data-index] td:nth-child(7)")
             .all()]
    assert shown and set(shown) <= {"inside", "near"}
    shot(page, "#view-risk", "ux-3-riskiest-sorted-filtered.png")
    # the support shares in the catalogue panel
    info = page.locator("#catalogue-info").inner_text()
    n = sum(status["support"].values())
    for name, k in status["support"].items():
        assert f"{name} {k} ({100 * k / n:.2g} %)" in info or f"{name} {k} (" in info, info


# --------------------------------------------------------------------------- progress
def test_a_running_catalogues_progress_counts_what_is_computed(server: Server,
                                                               page: Page) -> None:
    """The draw status said "running 11 % (0 of 300 scenarios)": the percentage counts the
    scenarios the workers have computed, the count was the stored ones (whole chunks)."""
    from app.db import chunkfile
    from app.db import repository as repo

    cid = server.catalogue(n=30, seed=4, chunk_size=10)  # three chunks stored
    db = server.db()
    try:
        with db.session() as s:  # ... of 300, the fourth chunk computing
            row = repo.get_catalogue(s, cid)
            row.status, row.n, row.n_chunks = "running", 300, 30
    finally:
        db.dispose()
    folder = chunkfile.progress_dir(server.data_dir, cid)
    folder.mkdir(parents=True, exist_ok=True)
    chunkfile.write_progress(folder, 3, 7)
    status = httpx.get(f"{server.base}/catalogues/{cid}").json()
    assert (status["scenarios_done"], status["scenarios_stored"]) == (37, 30)
    page.goto(f"{server.base}/dashboard/catalogues/{cid}")
    settle(page)
    info = page.locator("#catalogue-info").inner_text()
    assert "12 % (37 of 300 scenarios computed, 30 stored)" in info, info
    shot(page, "#catalogue-info", "ux-3-running-progress.png")


# --------------------------------------------------------------------------- view 3 plots
def _lopsided_rows(n: int) -> list[dict[str, Any]]:
    """n synthetic rows: one unpreventable cut-in among preventable ones, r_dep at t_p
    exactly 0 for 5 in 6 and 1e-7 ... 1e-1 for the rest, no RSS collision."""
    import numpy as np

    from tests.browser.factories import synthetic_rows

    rows = synthetic_rows(n, 21, 100)
    rng = np.random.default_rng(5)
    for i, r in enumerate(rows):
        r["class_"] = "unpreventable" if i == 7 else "preventable"
        r["r_dep_tp"] = 0.0 if i % 6 else float(10.0 ** rng.uniform(-7.0, -1.0))
        r["rss_collision"], r["rss_impact_speed"] = False, 0.0
    return rows


def test_class_bars_risk_at_tp_and_impact_speeds_are_readable(server: Server,
                                                              page: Page) -> None:
    """A single unpreventable case was invisible in the class bars, the r_dep-at-t_p
    histogram one spike at 0 and the impact speeds a comb of thin bars."""
    n = 300
    rows = _lopsided_rows(n)
    cid = server.catalogue(rows=rows, n=n, seed=21, chunk_size=100)
    page.goto(f"{server.base}/dashboard/catalogues/{cid}")
    settle(page)
    # the lone unpreventable bar is drawn tall enough to see (log axis)
    bars = page.locator("#class-counts .barlayer .point path")
    heights = [(bars.nth(i).bounding_box() or {"height": 0.0})["height"]
               for i in range(bars.count())]
    classes = traces(page, "class-counts")[0]
    assert classes["y"][2] == 1  # unpreventable
    assert heights[2] >= 10, heights
    # r_dep at t_p: the positive values on half decades, the zeros counted, not drawn
    positive = [r["r_dep_tp"] for r in rows if r["r_dep_tp"] > 0]
    drawn = {t["name"].split(":")[0]: t for t in traces(page, "rdep-hist")}
    scripted = drawn["scripted ego"]
    assert sum(scripted["y"]) == len(positive) == 50
    assert min(scripted["x"]) > -8 and max(scripted["x"]) < 0  # log10 of the bin centres
    assert f"{n - len(positive)} of {n} below 1e-8" in scripted["name"]
    # hand binning: half decade k holds [10^(k/2), 10^((k+1)/2)); bar centres are log10
    got = {math.floor(2 * x): y for x, y in zip(scripted["x"], scripted["y"], strict=True)
           if y}
    want: dict[int, int] = {}
    for v in positive:
        k = math.floor(2 * math.log10(v))
        want[k] = want.get(k, 0) + 1
    assert got == want
    # impact speeds: only the colliding drivers get bars (RSS: none), at most 20 bins
    impact = traces(page, "impact-hist")
    assert [t["name"].split(":")[0] for t in impact] == ["no reaction (scripted ego)",
                                                         "R157 careful driver"]
    assert all(len(t["x"]) <= 20 for t in impact)
    assert "RSS response: 0 of 300 collide" in (page.locator("#impact-hist").text_content()
                                                or "")
    widths = [(b.bounding_box() or {"width": 0.0})["width"]
              for b in page.locator("#impact-hist .barlayer .point path").all()]
    assert min(w for w in widths if w > 0) >= 6, widths
    shot(page, "#view-risk", "ux-3-readable-histograms.png")
