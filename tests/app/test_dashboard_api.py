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
from tests.browser.factories import prepare_data_dir, store_synthetic_catalogue, synthetic_rows

#: the payload bounds the dashboard promises (docs/dashboard.md)
MAX_POINTS_PER_PLOT = 2000
MAX_BARS = 60


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    data_dir = prepare_data_dir(tmp_path_factory.mktemp("dashboard"))
    # a generous time budget: a loaded machine must not turn the sampling reads into 422s
    settings = Settings(data_dir=data_dir, local_workers=0, chunk_size=2, warm_start=False,
                        trusted_hosts=["testserver"], sync_budget_seconds=600.0)
    app = create_app(settings)
    with TestClient(app) as c:
        yield c


def _ctx(client: TestClient) -> Any:
    return client.app.state.ctx  # type: ignore[attr-defined]


INF = float("inf")
#: six scored scenarios and one the builder refused, values chosen to count by hand:
#: (class, btn, ttr_true, none/r157_cc/rss impact speed (None: no collision), r_dep_tp,
#:  alarm_time, ttc)
HAND = [
    ("no_conflict", 0.0, INF, (None, None, None), 0.0, None, 2.5),
    ("preventable", 0.12, 2.0, (4.0, None, None), 0.02, 1.5, 1.0),
    ("preventable", 0.5, 1.3, (6.0, None, 1.0), 0.07, 0.8, 0.8),
    ("unpreventable", 1.04, 0.4, (8.5, 2.2, 3.0), 0.3, 0.3, 0.6),
    ("unavoidable", 1.3, 0.0, (10.0, 7.9, 7.0), 0.95, 0.0, INF),
    ("preventable", INF, 1.0, (3.0, None, None), 0.5, None, 1.5),
]


def _hand_catalogue(client: TestClient) -> str:
    """Seven scenarios in three chunks (HAND, then a row without scores)."""
    rows = []
    for i in range(7):
        params = {"p_y1": 0.04, "p_t": 2.0 + i, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
                  "p_v0": 25.0, "dv": 2.0, "gap": 10.0 * (i + 1)}
        row: dict[str, Any] = {"idx": i, "chunk_index": i // 3, "params": params,
                               "exposure_weight": 1.0, "summary": {}, "ttc": 2.0,
                               "risk": None, "error": None}
        if i < len(HAND):
            cls, btn, ttr, speeds, r_dep, alarm, ttc = HAND[i]
            row.update(class_=cls, btn=btn, a_req=btn * 7.59294, ttr_true=ttr,
                       ttr_manoeuvre="none" if cls == "unavoidable" else "brake",
                       ttc=None if ttc == INF else ttc, risk=1.0, risk_peak=1.0,
                       r_dep_tp=r_dep, r_dep_tp_r157=0.0, alarm_time=alarm, t_p=3.0)
            for driver, v in zip(("none", "r157_cc", "rss"), speeds, strict=True):
                row[f"{driver}_collision"] = v is not None
                row[f"{driver}_impact_speed"] = 0.0 if v is None else v
        else:
            row["error"] = "build: the cutter never enters the ego lane"
        rows.append(row)
    ctx = _ctx(client)
    return store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 7,
                                     chunk_size=3, rows=rows)


def _nonzero(hist: dict[str, Any]) -> dict[float, int]:
    """{left edge: count} of the non-empty bins."""
    return {round(e, 9): c for e, c in zip(hist["edges"], hist["counts"], strict=False) if c}


# --------------------------------------------------------------------------- page + static
@pytest.mark.slow
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
    ("/dashboard/api/catalogues/cat-nope/criticality", 404, "path.catalogue_id"),
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


@pytest.mark.slow
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
def test_catalogue_criticality_view_counts_by_hand(client: TestClient) -> None:
    cid = _hand_catalogue(client)
    r = client.get(f"/dashboard/api/catalogues/{cid}/criticality")
    assert r.status_code == 200, r.text
    view = r.json()
    assert view["n_rows"] == 7 and view["n_scored"] == 6 and view["n_unscored"] == 1
    classes = {c["name"]: c["count"] for c in view["classes"]}
    assert classes == {"no_conflict": 1, "preventable": 3, "unpreventable": 1,
                       "unavoidable": 1}
    # the labels say what the classes mean
    labels = {c["name"]: c["label"] for c in view["classes"]}
    assert labels["unavoidable"] == "unavoidable (nothing avoids it)"
    assert "careful driver avoids it" in labels["preventable"]
    # the same counts as the catalogue's status
    status = client.get(f"/catalogues/{cid}").json()["classes"]
    assert all(status[name] == n for name, n in classes.items())
    # btn: max finite 1.3 -> width 0.05 (0 ... 1.3 in 26 bins); one +inf counted apart
    btn = view["btn"]
    assert btn["edges"][0] == 0.0 and btn["edges"][-1] == pytest.approx(1.3)
    assert btn["edges"][1] == pytest.approx(0.05) and len(btn["counts"]) == 26
    assert _nonzero(btn) == {0.0: 1, 0.1: 1, 0.5: 1, 1.0: 1, 1.25: 1}
    assert btn["n_inf"] == 1 and btn["n_finite"] == 5 and btn["n"] == 6
    assert view["decel_max"] == pytest.approx(0.774 * 9.81)
    # ttr_true: max finite 2.0 -> width 0.05; the +inf ("no collision at constant speed")
    # counted, not dropped
    ttr = view["ttr_true"]
    assert _nonzero(ttr) == {0.0: 1, 0.4: 1, 1.0: 1, 1.3: 1, 1.95: 1}
    assert ttr["n_inf"] == 1 and ttr["n_null"] == 0
    # impact speeds of the colliding ones only: largest 10 m/s -> width 0.5 on 0 ... 10
    # (at most 20 bins: 40 made a comb of thin bars, issue 25)
    speeds = {d["driver"]: d["histogram"] for d in view["impact_speed"]}
    assert speeds["none"]["n"] == 5 and speeds["r157_cc"]["n"] == 2 and speeds["rss"]["n"] == 3
    assert speeds["none"]["edges"][1] == 0.5 and speeds["none"]["edges"][-1] == 10.0
    assert _nonzero(speeds["r157_cc"]) == {2.0: 1, 7.5: 1}
    assert _nonzero(speeds["none"]) == {3.0: 1, 4.0: 1, 6.0: 1, 8.5: 1, 9.5: 1}
    # r_dep at t_p: [0, 1e-8), then half decades 1e-8, 10^-7.5, ..., 1 (issue 25: 20 linear
    # bins drew one spike); 0 | 0.02 in [0.01, 0.0316) | 0.07 in [0.0316, 0.1) | 0.3 in
    # [0.1, 0.316) | 0.5 and 0.95 in [0.316, 1]
    r_dep = view["r_dep_tp"]["scripted"]
    assert len(r_dep["counts"]) == 17 and r_dep["edges"][:2] == [0.0, 1e-8]
    assert _nonzero(r_dep) == {0.0: 1, 0.01: 1, 0.031622777: 1, 0.1: 1, 0.316227766: 2}
    assert _nonzero(view["r_dep_tp"]["r157"]) == {0.0: 6}
    # alarm time: 4 values, 2 never (null)
    alarm = view["alarm_time"]
    assert alarm["n_finite"] == 4 and alarm["n_null"] == 2
    # scatter: finite TTC and btn -> indices 0, 1, 2, 3 (4: TTC inf, 5: btn inf)
    sc = view["scatter"]
    assert sc["index"] == [0, 1, 2, 3] and sc["n_ttc_inf"] == 1 and sc["n_btn_inf"] == 1
    assert sc["cls"] == ["no_conflict", "preventable", "preventable", "unpreventable"]
    assert sc["btn"] == [0.0, 0.12, 0.5, 1.04] and sc["ttc"] == [2.5, 1.0, 0.8, 0.6]
    # the riskiest by btn: +inf first, then 1.3, 1.04, ...; the unscored row is not listed
    top = view["top"]
    assert [t["index"] for t in top] == [5, 4, 3, 2, 1, 0]
    assert top[0]["btn"] == "Infinity" and top[0]["class"] == "preventable"
    assert top[1]["ttc"] is None and top[1]["ttr_manoeuvre"] == "none"
    d = view["diagnostics"]
    assert d["chunks"] == 3 and d["methods"] == ["rejection"]
    assert d["acceptance_mean"] == pytest.approx(0.2)  # chunks: 0.1, 0.2 and 0.3
    info = view["catalogue"]
    assert info["n"] == 7 and info["seed"] == 0 and info["p_region"]["estimate"] == 0.001


def test_sql_histogram_equals_numpy_on_stored_rows(client: TestClient) -> None:
    """The SQL counts against numpy's (aggregate.histogram) on a synthetic catalogue."""
    import numpy as np

    from app.dashboard import queries
    from app.dashboard.aggregate import histogram

    ctx = _ctx(client)
    rows = synthetic_rows(500, 3, 100)
    cid = store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 500,
                                    chunk_size=100, rows=rows)
    for name in ("btn", "ttr_true", "alarm_time", "r_dep_tp"):
        values = np.array([np.nan if r[name] is None else r[name] for r in rows])
        for edges in ([0.0, 0.1, 0.5, 1.0], np.linspace(0.0, 2.0, 41), [0.2, 0.3]):
            with ctx.db.read_session() as s:
                got = queries.column_histogram(s, cid, queries.column(name), edges)
            want = histogram(values, edges)
            for key in ("counts", "n", "n_finite", "below", "above", "n_nonfinite"):
                assert got[key] == want[key], (name, key)
            assert got["n_inf"] == int(np.isposinf(values).sum())
            assert got["n_null"] == int(np.isnan(values).sum())


def test_catalogue_shift_view_uses_the_catalogue_samples(client: TestClient) -> None:
    cid = _hand_catalogue(client)
    view = client.get(f"/dashboard/api/catalogues/{cid}/shift").json()
    assert view["source"] == "catalogue" and view["n"] == 7
    gap = {p["name"]: p for p in view["parameters"]}["gap"]
    assert gap["constrained"]["n"] == 7
    assert gap["mean_constrained"] == pytest.approx(40.0)  # 10, 20, ..., 70


@pytest.mark.slow
def test_ten_thousand_scenarios_give_a_bounded_payload(client: TestClient) -> None:
    ctx = _ctx(client)
    cid = store_synthetic_catalogue(ctx.db, ctx.data_dir, ctx.default_model_id, 10_000,
                                    seed=5, chunk_size=1000)
    r = client.get(f"/dashboard/api/catalogues/{cid}/criticality")
    assert r.status_code == 200
    view = r.json()
    assert view["n_rows"] == 10_000 and view["n_scored"] == 10_000
    s = view["scatter"]
    assert len(s["index"]) == len(s["ttc"]) == len(s["btn"]) == len(s["cls"])
    assert len(s["index"]) <= MAX_POINTS_PER_PLOT and s["n_shown"] == len(s["index"])
    hists = [view["btn"], view["ttr_true"], view["alarm_time"], *view["r_dep_tp"].values(),
             *(d["histogram"] for d in view["impact_speed"])]
    for h in hists:
        assert len(h["counts"]) <= MAX_BARS
    # every scored btn is in a bar or counted as +inf
    assert sum(view["btn"]["counts"]) + view["btn"]["n_inf"] == 10_000
    assert sum(c["count"] for c in view["classes"]) == 10_000
    assert len(view["top"]) == 10
    assert len(r.content) < 200_000  # bytes: what the page downloads for view 3
    shift = client.get(f"/dashboard/api/catalogues/{cid}/shift")
    assert all(len(p["constrained"]["counts"]) <= MAX_BARS for p in shift.json()["parameters"])
    assert len(shift.content) < 100_000


# --------------------------------------------------------------------------- view 4
@pytest.mark.slow
def test_scenario_view_of_a_real_catalogue(client: TestClient) -> None:
    # Wagner's scan asked for, so the stored risk_peak can be checked against the view's
    r = client.post("/catalogues", json={"n": 3, "seed": 11, "constraints": ["ttc<3"],
                                         "wagner_scan": True})
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
    stored = client.get(f"/catalogues/{cid}/scenarios", params={"offset": 1, "limit": 1,
                                                                  "order_by": "index"})
    row = stored.json()["scenarios"][0]
    # the risk recomputed for the view is the stored scenario risk (same riskcore)
    assert view["summary"]["risk"] == pytest.approx(row["risk_peak"], rel=1e-12)
    assert max(view["series"]["r_dep"]) == pytest.approx(row["risk_peak"], rel=1e-12)
    json.dumps(view, allow_nan=False)  # plain JSON
    # the stored criticality record, and the profiles computed for this scenario
    assert view["record"]["class"] == row["class"] and view["record"]["btn"] == row["btn"]
    prof = view["profiles"]
    assert prof is not None, view["profiles_error"]
    assert prof["t"] == view["t"] and prof["t_p"] == pytest.approx(row["t_p"], abs=1e-9)
    for name in ("r_dep", "r_ind", "r_dep_r157", "r_ind_r157"):
        assert len(prof[name]) == n_t
    assert len(prof["r157_ego"]["x"]) == n_t and len(prof["r157_ego"]["psi"]) == n_t
    # the R157 driver's ego is the scripted ego's car: its size, so view 4 can draw its box
    assert view["ego"]["length"] > 3 and view["ego"]["width"] > 1
    assert prof["r157_ego"]["length"] == view["ego"]["length"]
    assert prof["r157_ego"]["width"] == view["ego"]["width"]
    assert max(prof["r_dep"]) == pytest.approx(row["risk_peak"], rel=1e-12)
    if row["r157_cc_t_brake"] is not None:
        assert prof["r157_t_brake"] == pytest.approx(row["r157_cc_t_brake"], abs=1e-9)
        # before braking the R157 ego is the scripted one; after, it is behind it
        k = max(i for i, t in enumerate(view["t"]) if t <= row["r157_cc_t_brake"])
        assert prof["r157_ego"]["x"][:k + 1] == pytest.approx(view["ego"]["x"][:k + 1])
        assert prof["r157_ego"]["x"][-1] < view["ego"]["x"][-1]
    # without its chunk file (chunk 1 holds scenario 2) the scenario is rebuilt from its
    # stored parameters and seed on the model's lane width: the same risk
    for path in (_ctx(client).data_dir / "catalogues" / cid).glob("chunk_000001.*"):
        path.unlink()
    rebuilt = client.get(f"/dashboard/api/catalogues/{cid}/scenarios/2").json()
    assert rebuilt["trajectory_source"] == "rebuilt from the stored parameters"
    row2 = client.get(f"/catalogues/{cid}/scenarios", params={"offset": 2, "limit": 1,
                                                               "order_by": "index"})
    assert rebuilt["summary"]["risk"] == pytest.approx(row2.json()["scenarios"][0]["risk_peak"],
                                                       rel=1e-12)
    missing = client.get(f"/dashboard/api/catalogues/{cid}/scenarios/3")
    assert missing.status_code == 404 and missing.json()["error"]["field"] == "path.index"
    page = client.get(f"/dashboard/catalogues/{cid}", params={"scenario": 1})
    assert page.status_code == 200 and cid in page.text
    bad = client.get(f"/dashboard/catalogues/{cid}", params={"scenario": "first"})
    assert bad.status_code == 422 and "scenario must be a whole number" in bad.text
