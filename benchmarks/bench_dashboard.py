"""How fast is the dashboard for a 10,000-scenario catalogue? Prints the figures.

Starts the service (uvicorn subprocess, temporary data dir and SQLite database, the quick
default model of tests/browser/factories.py), stores a finished catalogue of 10,000
synthetic scenario rows (the dashboard's cost depends only on the stored rows), then
measures

* each JSON view of the page: time of the first (cold, computed) and of a repeated
  (cached) request, and the size of what is sent;
* the page in headless Chromium: from navigation to every plot drawn
  (``body[data-ready]`` and no request outstanding), first load and reload.

Run:  .venv/bin/python benchmarks/bench_dashboard.py [n_scenarios]
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_service import Server  # noqa: E402  (benchmarks/ is on sys.path as the script dir)

from app.db.database import Database  # noqa: E402
from tests.browser.factories import (  # noqa: E402
    CHROMIUM,
    CHROMIUM_ARGS,
    prepare_data_dir,
    store_synthetic_catalogue,
)


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} (shared machine)")
    with tempfile.TemporaryDirectory(prefix="bench-dashboard-") as tmp:
        data_dir = prepare_data_dir(Path(tmp))
        server = Server(data_dir, {"SCENGEN_LOCAL_WORKERS": "0"}, data_dir / "uvicorn.log")
        base = server.base
        try:
            server.wait(timeout=300)
            model_id = httpx.get(f"{base}/health").json()["default_model"]
            db = Database(f"sqlite:///{(data_dir / 'scengen.db').resolve()}")
            t0 = time.perf_counter()
            cid = store_synthetic_catalogue(db, data_dir, model_id, n, seed=1)
            other = store_synthetic_catalogue(db, data_dir, model_id, n, seed=2)
            db.dispose()
            print(f"stored two catalogues of {n} synthetic scenarios each in "
                  f"{time.perf_counter() - t0:.1f} s ({cid}, {other})")
            _api(base, cid)
            _page(base, cid, other)
        finally:
            server.stop()


def _api(base: str, cid: str) -> None:
    print("\nJSON views (cold = first request, computed; warm = repeated, cached):")
    print(f"  {'view':44s} {'cold ms':>8s} {'warm ms':>8s} {'kB':>7s}")
    with httpx.Client(base_url=base, timeout=300) as http:
        for path in (f"/dashboard/api/catalogues/{cid}/criticality",
                     f"/dashboard/api/catalogues/{cid}/shift",
                     "/dashboard/api/models/default/fit"):
            times = []
            size = 0
            for _ in range(2):
                t0 = time.perf_counter()
                r = http.get(path)
                times.append(1000 * (time.perf_counter() - t0))
                r.raise_for_status()
                size = len(r.content)
            name = path.replace(cid, "{id}")
            print(f"  {name:44s} {times[0]:8.0f} {times[1]:8.0f} {size / 1024:7.1f}")


def _page(base: str, cid: str, other: str) -> None:
    from playwright.sync_api import sync_playwright

    print("\npage /dashboard/catalogues/{id} in headless Chromium, navigation to every "
          "plot drawn:")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        for label, target in (("first load (plotly.js from the app)", cid),
                              ("reload", cid), ("reload", cid),
                              ("another catalogue, its views not cached", other)):
            t0 = time.perf_counter()
            page.goto(f"{base}/dashboard/catalogues/{target}", wait_until="commit")
            page.wait_for_selector(f"#alarm-hist[data-source='{target}']",
                                   timeout=120_000)
            risk_view = time.perf_counter() - t0
            page.wait_for_selector("body[data-ready='1']", timeout=120_000)
            page.wait_for_function("document.body.dataset.busy === '0'", timeout=120_000)
            elapsed = time.perf_counter() - t0
            marks = page.evaluate(
                "Object.fromEntries(performance.getEntriesByType('mark')"
                ".map(m => [m.name, m.startTime / 1000]))")
            if os.environ.get("BENCH_VERBOSE"):
                for e in page.evaluate("performance.getEntriesByType('resource').map(e => "
                                       "[e.name, Math.round(e.startTime), "
                                       "Math.round(e.duration)])"):
                    print("     ", e)
            points = page.locator("#ttc-btn .scatterlayer .point").count()
            bars = page.locator(".barlayer .point").count()
            print(f"  {label:42s} catalogue view {risk_view:5.2f} s, all views "
                  f"{elapsed:5.2f} s ({points} scatter points, {bars} bars drawn)")
            print(f"  {'':42s} in-page clock from navigation start: catalogue view "
                  f"{marks.get('scengen:catalogue-view', float('nan')):5.2f} s, all views "
                  f"{marks.get('scengen:all-views', float('nan')):5.2f} s")
        browser.close()


if __name__ == "__main__":
    main()
