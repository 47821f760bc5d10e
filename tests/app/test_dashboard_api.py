"""The dashboard's page, static files and JSON views through TestClient.

The service runs on a private SQLite store with a quickly fitted default model
(tests/browser/factories.py). Catalogue views are checked on hand-made stored rows whose
aggregates are counted here by hand, and on a 10,000-scenario catalogue for the payload
bounds that keep the page fast.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import Settings
from tests.browser.factories import prepare_data_dir, store_synthetic_catalogue

#: the payload bounds the dashboard promises (docs/dashboard.md)
MAX_POINTS_PER_PLOT = 2000
MAX_BARS = 60


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    data_dir = prepare_data_dir(tmp_path_factory.mktemp("dashboard"))
    settings = Settings(data_dir=data_dir, local_workers=0, chunk_size=2)
    app = create_app(settings)
    with TestClient(app) as c:
        yield c


def _ctx(client: TestClient) -> Any:
    return client.app.state.ctx  # type: ignore[attr-defined]


def _hand_catalogue(client: TestClient) -> str:
    """Six scenarios in two chunks, values chosen to count by hand."""
    risks = [0.0, 0.05, 0.5, 0.51, 0.99, None]
    ttcs = [0.5, 1.0, 2.0, float("inf"), 2.5, 1.5]
    ttrs: list[Any] = ["Infinity", 1.0, 0.0, 0.3, 0.0, None]
    evasions = [None, "brake", "none", "brake", "steer_left+brake", None]
    rows = []
    for i in range(6):
        params = {"p_y1": 0.04, "p_t": 2.0 + i, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
                  "p_v0": 25.0, "dv": 2.0, "gap": 10.0 * (i + 1)}
        summary = {} if risks[i] is None else {
            "risk": risks[i], "risk_ind": min(1.0, (risks[i] or 0.0) + 0.01),
            "min_ttr": ttrs[i], "min_ttr_evasion": evasions[i]}
        rows.append({"idx": i, "chunk_index": i // 3, "params": params,
                     "ttc": ttcs[i], "risk": risks[i], "exposure_weight": 1.0,
                     "summary": summary})
    ctx = _ctx(client)
    return store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 6,
                                     chunk_size=3, rows=rows)


# --------------------------------------------------------------------------- page + static
def test_page_and_plotly_are_served_by_the_app(client: TestClient) -> None:
    r = client.get("/dashboard")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert '<script src="/dashboard/static/plotly.min.js">' in r.text
    assert "http://" not in r.text and "https://" not in r.text  # nothing from the network
    js = client.get("/dashboard/static/plotly.min.js")
    assert js.status_code == 200 and "javascript" in js.headers["content-type"]
    assert js.text.lstrip().startswith("/**") and "plotly.js v" in js.text[:200]
    assert len(js.content) > 1_000_000
    # sent gzip-compressed, cached by ETag; the same bytes without gzip
    assert js.headers["content-encoding"] == "gzip"
    assert int(js.headers["content-length"]) < len(js.content) / 2
    again = client.get("/dashboard/static/plotly.min.js",
                       headers={"If-None-Match": js.headers["etag"]})
    assert again.status_code == 304
    plain = client.get("/dashboard/static/plotly.min.js", headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers and plain.content == js.content
    for name in ("dashboard.js", "dashboard.css"):
        assert client.get(f"/dashboard/static/{name}").status_code == 200


def test_unknown_static_file_is_a_404_in_the_error_shape(client: TestClient) -> None:
    r = client.get("/dashboard/static/secrets.py")
    assert r.status_code == 404
    assert r.json()["error"]["field"] == "path.name"


def test_unknown_catalogue_page_is_a_404_page_with_the_message(client: TestClient) -> None:
    r = client.get("/dashboard/catalogues/cat-nope<script>")
    assert r.status_code == 404 and r.headers["content-type"].startswith("text/html")
    assert "not found" in r.text
    assert "<script>" not in r.text.split("data-initial=")[1].split(">")[0]  # escaped


@pytest.mark.parametrize("path, status, field", [
    ("/dashboard/api/catalogues/cat-nope/risk", 404, "path.catalogue_id"),
    ("/dashboard/api/catalogues/cat-nope/shift", 404, "path.catalogue_id"),
    ("/dashboard/api/catalogues/cat-nope/scenarios/0", 404, "path.catalogue_id"),
    ("/dashboard/api/models/mdl-nope/fit", 404, "path.model_id"),
    ("/dashboard/api/models/default/fit?dataset=ds-nope", 404, "query.dataset"),
    ("/dashboard/api/models/default/shift?constraints=ttc%3Cx", 422, "query.constraints.0"),
    ("/dashboard/api/models/default/shift?constraints=speed%3C3", 422, "query.constraints.0"),
    ("/dashboard/api/models/default/shift?n=0", 422, "query.n"),
])
def test_bad_input_gives_a_4xx_in_the_error_shape(client: TestClient, path: str, status: int,
                                                  field: str) -> None:
    r = client.get(path)
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["status"] == status and err["field"] == field and err["message"]


# --------------------------------------------------------------------------- view 1 + 2
def test_model_fit_view_bins_the_whole_dataset(client: TestClient) -> None:
    n_cutins = client.get("/datasets/tno-cutin").json()["n_cutins"]
    view = client.get("/dashboard/api/models/default/fit").json()
    assert view["n_data"] == n_cutins
    names = [p["name"] for p in view["parameters"]]
    assert names == ["p_y1", "p_t", "p_a1", "p_a2", "p_a3", "p_v0", "dv", "gap"]
    for p in view["parameters"]:
        h = p["histogram"]
        assert sum(h["counts"]) == n_cutins  # the edges span the data
        assert len(h["counts"]) <= MAX_BARS
        assert p["density"] is not None and len(p["density"]["x"]) == len(p["density"]["y"])
        assert all(y >= 0 for y in p["density"]["y"])
    corner = view["corner"]
    assert corner["data"]["n_shown"] == min(n_cutins, 400)
    assert len(corner["model"]["values"]["gap"]) <= 400


def test_shift_preview_draws_inside_the_constraint(client: TestClient) -> None:
    view = client.get("/dashboard/api/models/default/shift",
                      params={"constraints": "gap<15; dv>0", "n": 200, "seed": 3}).json()
    assert view["constraints"] == ["gap<15", "dv>0"] and view["n"] == 200
    by_name = {p["name"]: p for p in view["parameters"]}
    gap = by_name["gap"]["constrained"]
    assert gap["n"] == 200
    # every constrained gap lies below 15 m: no bin starting at or above 15 holds any
    assert all(c == 0 for lo, c in zip(gap["edges"], gap["counts"], strict=False) if lo >= 15)
    assert by_name["dv"]["mean_constrained"] > 0
    assert by_name["gap"]["unconstrained"]["n"] == 5000


# --------------------------------------------------------------------------- view 3
def test_catalogue_risk_view_counts_by_hand(client: TestClient) -> None:
    cid = _hand_catalogue(client)
    view = client.get(f"/dashboard/api/catalogues/{cid}/risk").json()
    assert view["n_rows"] == 6 and view["n_scored"] == 5
    r_dep = view["risk_hist"]["r_dep"]
    assert len(r_dep["counts"]) == 50 and r_dep["edges"][0] == 0 and r_dep["edges"][-1] == 1
    # bins of width 0.02: 0.0 and 0.05 -> bins 0 and 2, 0.5 and 0.51 -> bin 25, 0.99 -> 49
    assert {i: c for i, c in enumerate(r_dep["counts"]) if c} == {0: 1, 2: 1, 25: 2, 49: 1}
    assert r_dep["n_nonfinite"] == 1  # the unscored one
    # min TTR: ∞ (no collision), 1.0, 0.0, 0.3, 0.0 on bins of 0.1 centred on 0, 0.1, ...
    ttr = view["ttr_hist"]
    assert {i: c for i, c in enumerate(ttr["counts"]) if c} == {0: 2, 3: 1, 10: 1}
    assert view["n_no_collision"] == 1
    ev = dict(zip(view["evasion"]["labels"], view["evasion"]["counts"], strict=True))
    assert ev == {"brake": 2, "no collision": 1, "steer_left+brake": 1, "unavoidable": 1}
    s = view["scatter"]
    # plottable: finite TTC and risk -> indices 0, 1, 2, 4 (3 has TTC ∞, 5 no risk)
    assert sorted(s["index"]) == [0, 1, 2, 4] and s["n_ttc_inf"] == 1
    assert dict(zip(s["index"], s["risk"], strict=True))[4] == 0.99
    d = view["diagnostics"]
    assert d["chunks"] == 2 and d["methods"] == ["rejection"]
    assert d["acceptance_mean"] == pytest.approx(0.15)  # chunks: 0.1 and 0.2
    assert d["ess_total"] == 6.0 and d["tau_max"] is None
    info = view["catalogue"]
    assert info["n"] == 6 and info["seed"] == 0 and info["p_region"]["estimate"] == 0.001


def test_catalogue_shift_view_uses_the_catalogue_samples(client: TestClient) -> None:
    cid = _hand_catalogue(client)
    view = client.get(f"/dashboard/api/catalogues/{cid}/shift").json()
    assert view["source"] == "catalogue" and view["n"] == 6
    gap = {p["name"]: p for p in view["parameters"]}["gap"]
    assert gap["constrained"]["n"] == 6
    assert gap["mean_constrained"] == pytest.approx(35.0)  # 10, 20, ..., 60


def test_ten_thousand_scenarios_give_a_bounded_payload(client: TestClient) -> None:
    ctx = _ctx(client)
    cid = store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 10_000,
                                    seed=5, chunk_size=1000)
    r = client.get(f"/dashboard/api/catalogues/{cid}/risk")
    assert r.status_code == 200
    view = r.json()
    assert view["n_rows"] == 10_000
    s = view["scatter"]
    assert len(s["index"]) == len(s["ttc"]) == len(s["risk"]) <= MAX_POINTS_PER_PLOT
    assert s["n_plottable"] == 10_000 and s["n_shown"] == len(s["index"])
    for h in (view["risk_hist"]["r_dep"], view["risk_hist"]["r_ind"], view["ttr_hist"]):
        assert len(h["counts"]) <= MAX_BARS
    assert sum(view["risk_hist"]["r_dep"]["counts"]) == 10_000
    assert len(r.content) < 200_000  # bytes: what the page downloads for view 3
    shift = client.get(f"/dashboard/api/catalogues/{cid}/shift")
    assert all(len(p["constrained"]["counts"]) <= MAX_BARS for p in shift.json()["parameters"])
    assert len(shift.content) < 100_000


# --------------------------------------------------------------------------- view 4
def test_scenario_view_of_a_real_catalogue(client: TestClient) -> None:
    r = client.post("/catalogues", json={"n": 3, "seed": 11, "constraints": ["ttc<3"]})
    assert r.status_code == 202, r.text
    cid = r.json()["id"]
    info: dict[str, Any] = {}
    for _ in range(1200):
        info = client.get(f"/catalogues/{cid}").json()
        if info["status"] not in ("queued", "running"):
            break
        time.sleep(0.1)
    assert info["status"] == "done", info
    view = client.get(f"/dashboard/api/catalogues/{cid}/scenarios/1").json()
    assert view["index"] == 1 and view["trajectory_source"] == "stored trajectories"
    n_t = len(view["t"])
    assert len(view["ego"]["x"]) == n_t and len(view["objects"][0]["y"]) == n_t
    for name in ("t", "r_dep", "r_ind", "ttc", "wttc", "thw", "min_ttr"):
        assert len(view["series"][name]) == n_t
    stored = client.get(f"/catalogues/{cid}/scenarios", params={"offset": 1, "limit": 1})
    row = stored.json()["scenarios"][0]
    # the risk recomputed for the view is the stored scenario risk (same riskcore)
    assert view["summary"]["risk"] == pytest.approx(row["risk_peak"], rel=1e-12)
    assert max(view["series"]["r_dep"]) == pytest.approx(row["risk_peak"], rel=1e-12)
    json.dumps(view, allow_nan=False)  # plain JSON
    # without its chunk file (chunk 1 holds scenario 2) the scenario is rebuilt from its
    # stored parameters and seed on the model's lane width: the same risk
    for path in (_ctx(client).data_dir / "catalogues" / cid).glob("chunk_000001.*"):
        path.unlink()
    rebuilt = client.get(f"/dashboard/api/catalogues/{cid}/scenarios/2").json()
    assert rebuilt["trajectory_source"] == "rebuilt from the stored parameters"
    row2 = client.get(f"/catalogues/{cid}/scenarios", params={"offset": 2, "limit": 1})
    assert rebuilt["summary"]["risk"] == pytest.approx(row2.json()["scenarios"][0]["risk_peak"],
                                                       rel=1e-12)
    missing = client.get(f"/dashboard/api/catalogues/{cid}/scenarios/3")
    assert missing.status_code == 404 and missing.json()["error"]["field"] == "path.index"
    page = client.get(f"/dashboard/catalogues/{cid}", params={"scenario": 1})
    assert page.status_code == 200 and cid in page.text
    bad = client.get(f"/dashboard/catalogues/{cid}", params={"scenario": "first"})
    assert bad.status_code == 422 and "scenario must be a whole number" in bad.text


def test_min_ttr_panel_and_evasion_chart_agree_on_no_collision(client: TestClient) -> None:
    """Issue 14 item 9: a scored row whose min TTR is stored as null (riskcore's "nothing
    collides") counts as "no collision" in both panels, as one stored as "Infinity" does."""
    rows = []
    for i, ttr in enumerate([None, "Infinity", None, 0.5]):
        summary = {"risk": 0.1, "risk_ind": 0.1, "min_ttr": ttr,
                   "min_ttr_evasion": "brake" if ttr == 0.5 else None}
        rows.append({"idx": i, "chunk_index": 0, "ttc": 2.0, "risk": 0.1,
                     "exposure_weight": 1.0, "summary": summary,
                     "params": {"p_y1": 0.0, "p_t": 2.0, "p_a1": 0.0, "p_a2": 0.0,
                                "p_a3": 0.0, "p_v0": 25.0, "dv": 2.0, "gap": 10.0}})
    ctx = _ctx(client)
    cid = store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 4,
                                    chunk_size=4, rows=rows)
    view = client.get(f"/dashboard/api/catalogues/{cid}/risk").json()
    ev = dict(zip(view["evasion"]["labels"], view["evasion"]["counts"], strict=True))
    assert ev["no collision"] == 3
    assert view["n_no_collision"] == 3
