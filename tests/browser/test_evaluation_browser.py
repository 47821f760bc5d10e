"""The dashboard's section 7 (a system under test) in headless Chromium: two evaluations
made with the real simulator (the SUT ``acc`` and the careful driver ``r157_cc``) are
shown; the table holds both rates, the failures list and the scatter hold what the view's
JSON says, and clicking a failing run drives it again; the Evaluate button passes the
"score the drive with TTR risk" checkbox as ``risk``. Without a careful evaluation the
section says how to get one and its button starts it. Screenshots:
``test-artifacts/dashboard/sut.png``, ``sut-no-careful.png``, ``4-evaluation-run.png`` (a
failing run opened in the scenario view, view 4)."""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from playwright.sync_api import BrowserContext, sync_playwright

from tests.app.factories import make_settings, share_models, uvicorn_service
from tests.browser.factories import CHROMIUM, CHROMIUM_ARGS, prepare_data_dir

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts" / "dashboard"
TIMEOUT_MS = 180_000


def _serve(tmp_path_factory: pytest.TempPathFactory, name: str, suts: tuple[str, ...],
           n: int, models: dict[str, Any], stopped: bool = False
           ) -> Iterator[tuple[str, dict[str, str]]]:
    """A service over a data dir holding finished evaluations of ``suts`` (n draws each);
    with ``stopped`` first (so not the newest) one of ``acc`` that the stop rule's
    ``max_runs`` ended (ids["stopped"]: its summary warns) and one of ``idm`` without any
    collision (ids["quiet"]). The evaluations are made with the model object ``models``
    holds (``share_models``: the module's two data dirs estimate its memo once)."""
    from app.services import evaluations as service
    from app.services.store import open_context

    data_dir = prepare_data_dir(tmp_path_factory.mktemp(name))
    with pytest.MonkeyPatch.context() as mp:
        share_models(mp, models)
        ctx = open_context(make_settings(data_dir))
    ids = {}
    try:
        if stopped:
            row = service.create(ctx, sut="acc", rhw=0.3, max_runs=200, seed=2,
                                 batch_size=200)
            assert service.run_job(ctx, row.id) == "done"
            ids["stopped"] = row.id
            # and one without any collision: idm, 100 draws
            row = service.create(ctx, sut="idm", n=100, seed=1, batch_size=100)
            assert service.run_job(ctx, row.id) == "done"
            ids["quiet"] = row.id
        for sut in suts:
            row = service.create(ctx, sut=sut, n=n, seed=1, batch_size=200)
            assert service.run_job(ctx, row.id) == "done"
            ids[sut] = row.id
    finally:
        ctx.close()
    env = dict(os.environ, SCENGEN_DATA_DIR=str(data_dir), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_RESUME_JOBS="false", SCENGEN_WARM_START="0")
    for var in ("SCENGEN_DATABASE_URL", "SCENGEN_DASK_SCHEDULER"):
        env.pop(var, None)
    with uvicorn_service(env, data_dir / "uvicorn.log") as base:
        yield base, ids


@pytest.fixture(scope="module")
def models() -> dict[str, Any]:
    """The model object the module's evaluations share (``share_models``)."""
    return {}


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory, models: dict[str, Any]
           ) -> Iterator[tuple[str, dict[str, str]]]:
    yield from _serve(tmp_path_factory, "sut-browser", ("r157_cc", "acc"), 400, models,
                      stopped=True)


@pytest.fixture(scope="module")
def served_alone(tmp_path_factory: pytest.TempPathFactory, models: dict[str, Any]
                 ) -> Iterator[tuple[str, dict[str, str]]]:
    """Only the SUT's evaluation: no careful driver's on this model and region."""
    yield from _serve(tmp_path_factory, "sut-browser-alone", ("acc",), 200, models)


def _finished(base: str, eid: str) -> dict:
    """GET /evaluations/{eid} once it is no longer queued or running (bounded polling)."""
    deadline = time.monotonic() + TIMEOUT_MS / 1000
    while time.monotonic() < deadline:
        st = httpx.get(f"{base}/evaluations/{eid}", timeout=60).json()
        if st["status"] not in ("queued", "running"):
            return st
        time.sleep(1.0)
    raise AssertionError(f"evaluation {eid} did not finish in time")


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
            page.wait_for_selector("body[data-ready='1']", timeout=TIMEOUT_MS)
            page.wait_for_selector("#sut-scatter[data-rendered='1']", timeout=TIMEOUT_MS)
            page.wait_for_timeout(1500)
            # the deep link lands on section 7 once the views above it have grown with
            # their data (below the sticky header: scroll-margin-top 140 px)
            top = page.evaluate("document.getElementById('view-sut')"
                                ".getBoundingClientRect().top")
            assert 0 <= top <= 160, f"#view-sut at {top} px from the top after the deep link"
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
            fig = view["figures"]
            # the draws and the simulated cut-ins among them, from the summary
            assert (f"{fig['collisions']} collisions in {fig['runs']} draws "
                    f"({fig['sut_runs']} simulated cut-ins;") in table
            # the draws the weight roulette left unrun, when it left any
            if fig["skipped_runs"]:
                assert (f"; {fig['skipped_runs']} over-sampled draws left unrun by the "
                        "weight roulette") in table
            else:
                assert "weight roulette" not in table
            # too few collisions or a tiny ESS: the warning replaces the speed-up, greyed
            acc_rows = page.locator("#sut-table tr", has_text="acc · ")
            if fig["unreliable"]:
                assert fig["unreliable"] in table
                assert acc_rows.nth(1).get_attribute("class") == "unreliable flagged"
                assert "vs naive MC" not in acc_rows.nth(1).inner_text()
            else:
                assert acc_rows.nth(1).get_attribute("class") is None
            if view["failures"]:
                # the columns explained: tooltips and a legend under the table
                for col in ("vs careful", "weight", "share of P"):
                    tip = page.locator("#sut-failures th", has_text=col).get_attribute("title")
                    assert tip and len(tip) > 20
                legend = page.locator("#sut-failures-legend").inner_text()
                assert "vs careful: worse, same or better than UN R157" in legend
                assert "importance weight p/q" in legend
                assert "share of P: the run's weight over the sum" in legend
                # the share is the server's, as a percentage; a pilot run has none
                cells = page.locator("#sut-failures tr[data-run] td:nth-child(2)")
                for i, r in enumerate(view["failures"]):
                    text = cells.nth(i).inner_text()
                    if r["counted"] is False:
                        assert text == "pilot (not counted)"
                    else:
                        assert text.endswith(" %")
                        assert float(text[:-2]) == pytest.approx(100 * r["share"], rel=6e-3)
                if sc["note"]:  # no risk asked: how to get it
                    assert "risk: true (--risk" in legend
            # every value of the failures list on one line (a weight like 8.25e-4 was
            # broken after its "e-", seen at 1400 px)
            lines = page.evaluate("""() => [...document.querySelectorAll(
                '#sut-failures tr[data-run] td')].map((td) => {
                  const r = document.createRange(); r.selectNodeContents(td);
                  return [td.innerText, new Set([...r.getClientRects()].map(
                    (q) => Math.round(q.top))).size]; })""")
            assert lines and all(n == 1 for _, n in lines), [t for t, n in lines if n != 1]
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
            assert page.locator("#sut-careful").get_attribute("data-state") == "done"
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.locator("#view-sut").screenshot(path=str(ARTIFACTS / "sut.png"))
            # Evaluate passes the risk checkbox (default off) as "risk"
            risk_box = page.locator("#eval-risk")
            assert risk_box.is_visible() and not risk_box.is_checked()
            assert "score the drive with TTR risk" in page.locator("#eval-form").inner_text()
            made = {}
            for checked in (False, True):
                risk_box.set_checked(checked)
                page.select_option("#sut-select", "acc")
                page.fill("#eval-n", "6")
                before = page.locator("#eval-select option").count()
                with page.expect_request(lambda r: r.url == f"{base}/evaluations"
                                         and r.method == "POST") as req:
                    page.click("#eval-button")
                body = json.loads(req.value.post_data or "{}")
                assert body["risk"] is checked and body["sut"] == "acc" and body["n"] == 6
                # the list is reloaded with the new evaluation selected
                page.wait_for_function(
                    f"document.querySelectorAll('#eval-select option').length > {before}",
                    timeout=TIMEOUT_MS)
                made[checked] = page.locator("#eval-select").input_value()
            assert made[False] != made[True]
            for checked, eid in made.items():
                st = _finished(base, eid)
                assert st["status"] == "done" and st["spec"]["risk"] is checked
                runs = httpx.get(f"{base}/evaluations/{eid}/runs", params={"limit": 50},
                                 timeout=60).json()["runs"]
                peaks = [r["r_dep_peak"] for r in runs]
                assert peaks
                # with risk every simulated run has its peak r_dep; without it none has
                if checked:
                    assert all(isinstance(p, float) and 0.0 <= p <= 1.0 for p in peaks)
                else:
                    assert all(p is None for p in peaks)
            assert errors == []
            assert outside == []
        finally:
            browser.close()


def test_without_a_careful_evaluation_the_section_says_how_and_starts_one(
        served_alone: tuple[str, dict[str, str]]) -> None:
    base, ids = served_alone
    view = httpx.get(f"{base}/dashboard/api/evaluations/{ids['acc']}", timeout=120).json()
    assert view["careful"] is None
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 1000})
            errors: list[str] = []
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{base}/dashboard#view-sut")
            page.wait_for_selector("#sut-note[data-state=done]", timeout=TIMEOUT_MS)
            table = page.locator("#sut-table").inner_text()
            assert "acc · collisions per hour" in table
            assert "no evaluation of r157_cc on this model and region yet" in table
            box = page.locator("#sut-careful")
            assert box.get_attribute("data-state") == "none"
            how = box.inner_text()
            assert "Evaluate r157_cc here" in how and "POST /evaluations" in how
            assert json.dumps(view["careful_request"], separators=(",", ":")) in how
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.locator("#view-sut").screenshot(path=str(ARTIFACTS / "sut-no-careful.png"))
            with page.expect_request(lambda r: r.url == f"{base}/evaluations"
                                     and r.method == "POST") as req:
                page.click("#careful-button")
            assert json.loads(req.value.post_data or "{}") == view["careful_request"]
            # its progress, then its rate beside the SUT's (the section polls it)
            page.wait_for_selector("#sut-careful[data-state=running], "
                                   "#sut-careful[data-state=done]", state="attached",
                                   timeout=TIMEOUT_MS)
            page.wait_for_selector("#sut-careful[data-state=done]", state="attached",
                                   timeout=TIMEOUT_MS)
            table = page.locator("#sut-table").inner_text()
            assert "r157_cc (careful driver) · collisions per hour" in table
            assert "no evaluation of r157_cc" not in table
            # the SUT's evaluation stays the one shown
            assert page.locator("#eval-select").input_value() == ids["acc"]
            assert errors == []
        finally:
            browser.close()


def test_a_failing_run_opens_in_the_scenario_view(served: tuple[str, dict[str, str]],
                                                  context: BrowserContext) -> None:
    """Issue's wording: one run's speed, acceleration and r_dep beside the careful driver's
    *in the scenario view*. The run's panel is part of view 4, its heading says what it is,
    a click on a failing run in section 7 draws that run there and moves the page to it,
    and the panel links back to section 7. (Last in this module: it uses the conftest's
    browser, started once the tests above have closed their own Playwright.)"""
    base, ids = served
    view = httpx.get(f"{base}/dashboard/api/evaluations/{ids['acc']}", timeout=120).json()
    failures = view["failures"]
    assert len(failures) >= 2  # acc, 400 draws, seed 1: a few collide
    page = context.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"{base}/dashboard#view-sut")
    page.wait_for_selector("#sut-note[data-state=done]", timeout=TIMEOUT_MS)
    # the evaluation of 400 draws (the test above adds two of 6 draws, newer)
    page.select_option("#eval-select", ids["acc"])
    # its first failing run (the largest weight) is drawn in view 4, beside the careful
    # driver
    plot = "#view-scenario #scenario-run #sut-run-plot"
    page.wait_for_selector(f"{plot}[data-source='{ids['acc']}#{failures[0]['run']}']"
                           "[data-rendered='1']", timeout=TIMEOUT_MS)
    assert "4 · Scenario" in page.locator("#view-scenario h2").inner_text()
    assert "a run of an evaluation" in page.locator("#view-scenario h2").inner_text()
    heading = page.locator("#scenario-run h3").inner_text()
    assert "system under test beside the careful driver" in heading
    names = page.evaluate("""() => document.getElementById('sut-run-plot').data
                             .map((t) => t.name)""")
    assert {"acc speed", "acc accel", "careful speed", "careful accel"} <= set(names)
    # the rates and probabilities of section 7's table in one notation: before, 0.00131
    # [8.09e-4, 0.00213] (two notations in one interval)
    cells = page.evaluate("""() => [...document.querySelectorAll('#sut-table tr')].slice(1)
        .flatMap((tr) => [...tr.querySelectorAll('td')].slice(0, 3).map((td) => td.innerText))""")
    numbers = [x for c in cells for x in re.findall(r"[-0-9.e]+", c)]
    assert numbers and all(re.fullmatch(r"-?\d\.\d\de[-+]\d+", x) for x in numbers), numbers
    # every series ends where the drive ends (trailing nulls stretched the time axis past
    # a collision by seconds)
    assert page.evaluate("""() => document.getElementById('sut-run-plot').data.every(
        (t) => t.y.length > 0 && t.y[t.y.length - 1] !== null)""")
    note = page.locator("#sut-failures p.note:not(#sut-failures-legend)").inner_text()
    if len(failures) < view["failures_total"]:
        counted = sum(1 for r in failures if r["counted"])
        assert f"the {counted} that carry most of P, largest weight first" in note
    else:
        assert "largest weight first (those that carry most of P)" in note
    # section 7 no longer holds the profile; it says where it is
    assert page.locator("#view-sut #sut-run-plot").count() == 0
    where = page.locator("#view-sut a[href='#scenario-run']")
    assert where.count() == 1 and "view 4" in where.inner_text()
    # a click on another failing run draws it in view 4 and scrolls there
    second = failures[1]["run"]
    page.locator("#sut-failures tr[data-run]").nth(1).click()
    page.wait_for_selector(f"{plot}[data-source='{ids['acc']}#{second}']",
                           timeout=TIMEOUT_MS)
    info = page.locator("#sut-run-info")
    assert f"Run {second}: acc " in info.inner_text()
    assert f"(evaluation {ids['acc']})" in info.inner_text()
    # the impact speed is relative: said so beside a plot of the ego's own speed
    assert "collides at a relative speed of" in info.inner_text()
    page.wait_for_function("""() => { const r = document.getElementById('scenario-run')
        .getBoundingClientRect(); return r.top >= 0 && r.top < window.innerHeight / 2; }""")
    # not hidden under the sticky header
    header = page.locator("header").bounding_box()
    panel = page.locator("#scenario-run h3").bounding_box()
    assert header is not None and panel is not None
    assert panel["y"] >= header["y"] + header["height"]
    assert info.locator("a[href='#view-sut']").count() == 1
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.locator("#scenario-run").screenshot(path=str(ARTIFACTS / "4-evaluation-run.png"))
    assert errors == []


def test_every_warning_is_shown_and_intervals_stay_on_one_line(
        served: tuple[str, dict[str, str]], context: BrowserContext) -> None:
    """A campaign the stop rule's max_runs ended warns in its summary ("stopped at
    max_runs ...") but the section showed only the few-collisions / ESS flag: the warning
    was nowhere on the page. Now every warning of the SUT's and the careful driver's
    summaries is listed under the table. And an interval was broken over two lines
    ("[1.49e-3," / "2.74e-3]") at 1400 px. Screenshot: ``sut-warnings.png``."""
    base, ids = served
    view = httpx.get(f"{base}/dashboard/api/evaluations/{ids['stopped']}", timeout=120).json()
    warnings = view["figures"]["warnings"]
    assert any(w.startswith("stopped at max_runs") for w in warnings), warnings
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"{base}/dashboard#view-sut")
    page.wait_for_selector("#sut-note[data-state=done]", timeout=TIMEOUT_MS)
    page.select_option("#eval-select", ids["stopped"])
    page.wait_for_selector(f"#sut-note[data-state=done]:has-text('{ids['stopped']}')",
                           timeout=TIMEOUT_MS)
    listed = page.locator("#sut-warnings")
    assert listed.is_visible()
    items = listed.locator("li").all_inner_texts()
    careful = (view["careful"] or {}).get("figures") or {}
    assert items == ([f"acc: {w}" for w in warnings]
                     + [f"r157_cc: {w}" for w in careful.get("warnings") or []])
    # each cell of the rates table but the last (a sentence) on one line
    lines = page.evaluate("""() => [...document.querySelectorAll('#sut-table tr')].slice(1)
        .flatMap((tr) => [...tr.querySelectorAll('td')].slice(0, -1)).map((td) => {
          const r = document.createRange(); r.selectNodeContents(td);
          return [td.innerText, new Set([...r.getClientRects()].map(
            (q) => Math.round(q.top))).size]; })""")
    assert lines and all(n == 1 for _, n in lines), [t for t, n in lines if n != 1]
    # the scatter's title (with the note why r_dep is missing) inside its plot: it ran
    # past both edges
    page.wait_for_selector("#sut-scatter[data-rendered='1']", timeout=TIMEOUT_MS)
    inside = page.evaluate("""() => { const d = document.getElementById('sut-scatter')
        .getBoundingClientRect(); const t = document.querySelector('#sut-scatter .gtitle')
        .getBoundingClientRect(); return [t.width > 0, t.left >= d.left, t.right <= d.right,
        t.top >= d.top]; }""")
    assert inside == [True, True, True, True], inside
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.locator("#view-sut").screenshot(path=str(ARTIFACTS / "sut-warnings.png"))
    # an evaluation without warnings: no list
    page.select_option("#eval-select", ids["acc"])
    page.wait_for_selector(f"#sut-note[data-state=done]:has-text('{ids['acc']}')",
                           timeout=TIMEOUT_MS)
    acc = httpx.get(f"{base}/dashboard/api/evaluations/{ids['acc']}", timeout=120).json()
    shown = page.locator("#sut-warnings li").count()
    assert shown == len(acc["figures"]["warnings"]) + len(
        ((acc["careful"] or {}).get("figures") or {}).get("warnings") or [])
    assert page.locator("#sut-warnings").is_visible() == (shown > 0)
    assert errors == []


def test_without_a_collision_both_rows_give_the_upper_bound(
        served: tuple[str, dict[str, str]], context: BrowserContext) -> None:
    """No run collided: the rate per hour read "0 [–, –]" (as if it never collides) while
    only the P row gave the 95 % upper bound; both give their bound now."""
    base, ids = served
    view = httpx.get(f"{base}/dashboard/api/evaluations/{ids['quiet']}", timeout=120).json()
    fig = view["figures"]
    assert fig["collisions"] == 0
    page = context.new_page()
    page.goto(f"{base}/dashboard#view-sut")
    page.wait_for_selector("#sut-note[data-state=done]", timeout=TIMEOUT_MS)
    page.select_option("#eval-select", ids["quiet"])
    page.wait_for_selector(f"#sut-note[data-state=done]:has-text('{ids['quiet']}')",
                           timeout=TIMEOUT_MS)
    rows = page.locator("#sut-table tr", has_text="idm · ")
    for k, key in enumerate(("rate_per_hour", "p_collision")):
        bound = fig[key]["upper_bound"]
        assert bound is not None and bound > 0
        cells = rows.nth(k).locator("td").all_inner_texts()
        # JavaScript's toExponential(2): 7.13e-2, 1.16e+0 (Python: 7.13e-02, 1.16e+00)
        text = re.sub(r"e([+-])0(\d)", r"e\1\2", f"{bound:.2e}")
        assert cells[1] == f"≤ {text} (95 % bound)", cells
    assert "no collision in 100 draws" in page.locator("#sut-warnings").inner_text()
    # the scatter's impact speeds (all 0) on an axis that starts at 0 (it ran from -1)
    page.wait_for_selector("#sut-scatter[data-rendered='1']", timeout=TIMEOUT_MS)
    low = page.evaluate("() => document.getElementById('sut-scatter')._fullLayout"
                        ".yaxis.range[0]")
    assert low >= 0, low
