"""Catalogues over HTTP: 202 + id, status with progress/counts/P(A)/statistics, paging and
filters, every export format, delete, and the errors."""

from __future__ import annotations

import csv
import io
import json
import re
import zipfile
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest

from tests.app.factories import wait_for

N = 12


def _finished(client: Any, cid: str) -> dict[str, Any]:
    state: dict[str, Any] = {}

    def done() -> bool:
        state.update(client.get(f"/catalogues/{cid}").json())
        return state["status"] in ("done", "failed")

    wait_for(done, f"catalogue {cid}")
    return state


@pytest.fixture(scope="module")
def catalogue(client: Any) -> dict[str, Any]:
    """A scored catalogue with Wagner's scan asked for (so every score column is filled)."""
    r = client.post("/catalogues", json={"n": N, "seed": 9, "constraints": ["ttc<3"],
                                         "chunk_size": 5, "wagner_scan": True})
    assert r.status_code == 202, r.text
    body = r.json()
    assert body["status"] == "queued" and body["href"] == f"/catalogues/{body['id']}"
    return _finished(client, body["id"])


@pytest.mark.slow
def test_status_counts_p_region_and_statistics(catalogue: dict[str, Any]) -> None:
    assert catalogue["status"] == "done", catalogue["error"]
    assert catalogue["wagner_scan"] is True
    assert catalogue["n"] == N and catalogue["scenarios_stored"] == N
    assert catalogue["chunks"] == {"total": 3, "done": 3} and catalogue["progress"] == 1.0
    p = catalogue["p_region"]
    assert 0.0 < p["estimate"] < 1.0 and p["ci"][0] <= p["estimate"] <= p["ci"][1]
    risk = catalogue["summary"]["risk"]
    assert risk["count"] == N and 0.0 <= risk["min"] <= risk["p50"] <= risk["max"] <= 1.0
    assert catalogue["summary"]["ttc"]["max"] < 3.0
    assert catalogue["finished_at"] is not None


def test_status_rates_with_both_intervals_and_weights_summing_to_the_rate(
        catalogue: dict[str, Any]) -> None:
    """issue 12: the default (TNO) model has 63 h of exposure and bootstrap refits, so a
    catalogue's status gives its region's cut-ins per hour with the Monte Carlo and the
    model interval, and its stored exposure weights (P(A) / n each) times the rate of all
    cut-ins (208 / 63 h) add up to that rate."""
    p = catalogue["p_region"]
    rates = catalogue["rates"]
    lam = 208 / 63.0  # hand-computed: the embedded table's rows over the source's hours
    assert rates["exposure"]["n_events"] == 208 and rates["exposure"]["hours"] == 63.0
    hour = rates["per_hour"]
    assert hour["estimate"] == pytest.approx(lam * p["estimate"], rel=1e-12)
    assert hour["mc_ci"] == pytest.approx([lam * p["ci"][0], lam * p["ci"][1]], rel=1e-12)
    assert p["mc_ci"] == pytest.approx(p["ci"], rel=1e-12)
    lo, hi = p["model_ci"]
    assert 0 < lo < p["estimate"] < hi  # the fit's interval: wider than the estimator's
    assert hi / lo > (p["ci"][1] / p["ci"][0])
    assert hour["model_ci"][0] < hour["estimate"] < hour["model_ci"][1]
    assert rates["per_1e6_km"] is None  # the TNO source gives no distance
    w = rates["from_weights"]
    assert w["sum_weights"] == pytest.approx(p["estimate"], rel=1e-9)
    assert w["per_hour"] == pytest.approx(hour["estimate"], rel=1e-9)
    assert p["model_interval"]["n_boot"] >= 2 and p["model_interval"]["lower_resolved"]


def test_rows_export_and_status_carry_the_data_support(client: Any,
                                                      catalogue: dict[str, Any]) -> None:
    """Issue 25 item 1: every stored scenario says what the data support (the model's own
    measures of its parameters, passed through), the CSV has the columns, and the status
    counts each support class (zeros included) and each criticality class."""
    import numpy as np

    from datasets import PARAM_NAMES

    cid = catalogue["id"]
    rows = client.get(f"/catalogues/{cid}/scenarios",
                      params={"limit": 100, "order_by": "index"}).json()["scenarios"]
    model = client.app.state.ctx.model(catalogue["model"])
    m = model.support_measures(np.array([[s["params"][k] for k in PARAM_NAMES] for s in rows]),
                               with_density=True)
    for i, s in enumerate(rows):
        want = m.record(i)
        assert s["support"] == want["support"] in ("inside", "near", "extrapolated")
        assert s["support_distance"] == pytest.approx(want["support_distance"], rel=1e-12)
        assert s["support_excess"] == pytest.approx(want["support_excess"], rel=1e-12, abs=0)
        assert s["support_nearest"] == want["support_nearest"]
        assert len(s["support_outside"]) == len(want["support_outside"])
    status = client.get(f"/catalogues/{cid}").json()
    tally = {c: sum(1 for s in rows if s["support"] == c)
             for c in ("inside", "near", "extrapolated")}
    assert status["support"] == tally  # every class, zeros included, in this order
    assert list(status["classes"]) == ["no_conflict", "preventable", "unpreventable",
                                       "unavoidable"]
    assert sum(status["classes"].values()) == N
    text = client.get(f"/catalogues/{cid}/export", params={"format": "csv"}).text
    table = list(csv.DictReader(io.StringIO(text)))
    by_index = {s["index"]: s for s in rows}
    for r in table:
        assert r["support"] == by_index[int(r["index"])]["support"]


def test_scenarios_page_and_filter(client: Any, catalogue: dict[str, Any]) -> None:
    cid = catalogue["id"]
    all_rows = client.get(f"/catalogues/{cid}/scenarios",
                          params={"limit": 100, "order_by": "index"}).json()
    assert all_rows["total"] == N
    assert [s["index"] for s in all_rows["scenarios"]] == list(range(N))
    page = client.get(f"/catalogues/{cid}/scenarios",
                      params={"offset": 10, "limit": 5, "order_by": "index"}).json()
    assert [s["index"] for s in page["scenarios"]] == [10, 11]
    ttcs = sorted(s["ttc"] for s in all_rows["scenarios"])
    cut = ttcs[N // 2]
    low = client.get(f"/catalogues/{cid}/scenarios", params={"ttc_max": cut}).json()
    assert low["total"] == sum(1 for t in ttcs if t <= cut)
    assert all(s["ttc"] <= cut for s in low["scenarios"])
    risks = sorted(s["risk_peak"] for s in all_rows["scenarios"])  # the risk filter's field
    high = client.get(f"/catalogues/{cid}/scenarios", params={"risk_min": risks[-3]}).json()
    assert high["total"] == sum(1 for r in risks if r >= risks[-3])
    for s in all_rows["scenarios"]:
        assert s["params"]["gap"] / s["params"]["dv"] == pytest.approx(s["ttc"])
        assert set(s) >= {"risk_peak", "btn", "class", "t_p", "error"}  # the flat record


def test_scenarios_ranked_by_criticality(client: Any, catalogue: dict[str, Any]) -> None:
    cid = catalogue["id"]
    url = f"/catalogues/{cid}/scenarios"
    everything = client.get(url, params={"limit": 100, "order_by": "index"}).json()["scenarios"]
    # default: btn, highest first (ties by index)
    ranked = client.get(url, params={"limit": 100}).json()["scenarios"]
    expect = sorted(everything, key=lambda s: (-float(s["btn"]), s["index"]))
    assert [s["index"] for s in ranked] == [s["index"] for s in expect]
    # any numeric field, ascending on request
    up = client.get(url, params={"order_by": "ttr_true", "desc": "false"}).json()["scenarios"]
    values = [float(s["ttr_true"]) for s in up]
    assert values == sorted(values)
    # ranges on any numeric field, yes/no fields, classes
    cut = sorted(float(s["a_req"]) for s in everything)[N // 2]
    r = client.get(url, params={"a_req_min": cut}).json()
    assert r["total"] == sum(1 for s in everything if float(s["a_req"]) >= cut)
    r = client.get(url, params={"r157_cc_collision": "false"}).json()
    assert r["total"] == sum(1 for s in everything if s["r157_cc_collision"] is False)
    cls = everything[0]["class"]
    r = client.get(url, params={"class": cls}).json()
    assert r["total"] == sum(1 for s in everything if s["class"] == cls)
    # the data support (issue 25): one class or several, counted as the status counts
    status = client.get(f"/catalogues/{cid}").json()
    for keep in (["inside"], ["near", "extrapolated"]):
        kept = client.get(url, params={"support": keep, "limit": 100}).json()
        assert kept["total"] == sum(status["support"][k] for k in keep)
        assert kept["total"] == sum(1 for s in everything if s["support"] in keep)
        assert all(s["support"] in keep for s in kept["scenarios"])
    # the status counts the classes and summarises the margins
    assert sum(status["classes"].values()) == N
    assert status["classes"][cls] == r["total"]
    btn = status["summary"]["btn"]
    assert btn["count"] + btn["count_inf"] == N
    assert btn["p05"] <= btn["p25"] <= btn["p50"] <= btn["p75"] <= btn["p95"]
    # bad input names the parameter
    for params, field in (({"order_by": "nope"}, "query.order_by"),
                          ({"class": "dangerous"}, "query.class"),
                          ({"support": "outside"}, "query.support"),
                          ({"btn_min": "high"}, "query.btn_min"),
                          ({"r157_cc_collision": "maybe"}, "query.r157_cc_collision"),
                          ({"colour": "red"}, "query.colour")):
        r = client.get(url, params=params)
        assert r.status_code == 422 and r.json()["error"]["field"] == field, r.text


def test_export_every_format(client: Any, catalogue: dict[str, Any]) -> None:
    cid = catalogue["id"]
    r = client.get(f"/catalogues/{cid}/export", params={"format": "jsonl"})
    assert r.status_code == 200
    lines = [json.loads(line) for line in r.text.splitlines() if line.strip()]
    assert lines[0]["kind"] == "manifest" and lines[0]["manifest"]["seed"] == 9
    assert lines[0]["manifest"]["constraints"] == ["ttc<3"]
    scenarios = [x for x in lines if x["kind"] == "scenario"]
    assert len(scenarios) == N
    rows = client.get(f"/catalogues/{cid}/scenarios",
                      params={"limit": 100, "order_by": "index"}).json()
    for line, row in zip(scenarios, rows["scenarios"], strict=True):
        assert line["scenario"]["params"] == pytest.approx(row["params"])
        assert line["summary"]["risk_peak"] == row["risk_peak"]
    r = client.get(f"/catalogues/{cid}/export", params={"format": "csv"})
    assert r.status_code == 200
    table = list(csv.DictReader(io.StringIO(r.text)))
    assert len(table) == N
    # the columns are the record's (no score column of an older schema that stays empty)
    assert not {"risk", "risk_ind", "min_ttr", "min_ttc", "step_of_max_risk"} & set(table[0])
    assert {"exposure_weight", "ttr_true", "class", "risk_peak", "error"} <= set(table[0])
    # issue 25: every column's unit is documented (docs/exports.md's units table)
    doc = (Path(__file__).resolve().parents[3] / "docs" / "exports.md").read_text()
    units = doc[doc.index("| column | unit | what |"):]
    units = units[:units.index("\n\n")]
    named = set(re.findall(r"`([a-z0-9_]+)`", units))
    assert set(table[0]) <= named, set(table[0]) - named
    empty = [c for c in table[0] if c != "error" and all(row[c] == "" for row in table)]
    assert empty == [] or set(empty) <= {"scenario_id", "alarm_time", "r157_cc_t_brake",
                                         "rss_t_brake", "ttr_manoeuvre"}, empty
    r = client.get(f"/catalogues/{cid}/export", params={"format": "parquet"})
    assert r.status_code == 200
    assert pq.read_table(io.BytesIO(r.content)).num_rows == N
    r = client.get(f"/catalogues/{cid}/export", params={"format": "xosc"})
    assert r.status_code == 200
    zf = zipfile.ZipFile(io.BytesIO(r.content))
    names = zf.namelist()
    assert sum(name.startswith("scenario_") for name in names) == N
    assert "cutin_distribution.xosc" in names
    assert b'value="ego_vehicle"' in zf.read("scenario_0000000.xosc")  # test mode: default
    r = client.get(f"/catalogues/{cid}/export", params={"format": "xosc", "mode": "replay"})
    assert r.status_code == 200
    replay = zipfile.ZipFile(io.BytesIO(r.content)).read("scenario_0000000.xosc")
    assert b'value="ego_vehicle"' not in replay and b'"scengen.mode" value="replay"' in replay
    r = client.get(f"/catalogues/{cid}/export", params={"format": "csv", "mode": "replay"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.mode"
    r = client.get(f"/catalogues/{cid}/export", params={"format": "xosc", "mode": "live"})
    assert r.status_code == 422
    r = client.get(f"/catalogues/{cid}/export", params={"format": "commonroad"})
    assert r.status_code == 200
    names = zipfile.ZipFile(io.BytesIO(r.content)).namelist()
    assert sum(name.endswith(".xml") for name in names) == N


@pytest.mark.slow
def test_list_and_delete(client: Any) -> None:
    r = client.post("/catalogues", json={"n": 3, "seed": 1, "score": False})
    cid = r.json()["id"]
    assert cid in [c["id"] for c in client.get("/catalogues").json()["catalogues"]]
    _finished(client, cid)
    assert client.delete(f"/catalogues/{cid}").status_code == 204
    for path in (f"/catalogues/{cid}", f"/catalogues/{cid}/scenarios",
                 f"/catalogues/{cid}/export"):
        r = client.get(path)
        assert r.status_code == 404 and r.json()["error"]["field"] == "path.catalogue_id"
    assert client.delete(f"/catalogues/{cid}").status_code == 404
    data_dir = client.app.state.ctx.data_dir
    assert not (data_dir / "catalogues" / cid).exists()


@pytest.mark.parametrize(("body", "status", "field"), [
    ({}, 422, "body.n"),
    ({"n": 0}, 422, "body.n"),
    ({"n": 2_000_000}, 422, "body.n"),
    ({"n": 5, "constraints": ["ttc<"]}, 422, "body.constraints.0"),
    ({"n": 5, "sampler": "x"}, 422, "body.sampler"),
    ({"n": 5, "chunk_size": 0}, 422, "body.chunk_size"),
    ({"n": 5, "model": "nope"}, 404, "body.model"),
])
def test_create_errors(client: Any, body: dict[str, Any], status: int, field: str) -> None:
    r = client.post("/catalogues", json=body)
    assert r.status_code == status, r.text
    assert r.json()["error"]["field"] == field


def test_export_and_paging_errors(client: Any, catalogue: dict[str, Any]) -> None:
    cid = catalogue["id"]
    r = client.get(f"/catalogues/{cid}/export", params={"format": "pdf"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.format"
    r = client.get(f"/catalogues/{cid}/scenarios", params={"ttc_max": "inf"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.ttc_max"
    r = client.get(f"/catalogues/{cid}/scenarios", params={"limit": 5000})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.limit"


def test_export_of_an_unfinished_catalogue_is_409(client: Any) -> None:
    from app.services import catalogues

    ctx = client.app.state.ctx
    row = catalogues.create(ctx, n=3, seed=2, constraints=["ttc<3"])  # queued, never run
    r = client.get(f"/catalogues/{row.id}/export")
    assert r.status_code == 409 and "queued" in r.json()["error"]["message"]
    assert client.get(f"/catalogues/{row.id}").json()["progress"] == 0.0


def test_status_of_a_running_catalogue_counts_the_workers_reports(client: Any) -> None:
    # issue 14 item 6: the status moves per scenario while a chunk is being computed
    from app.db import chunkfile
    from app.db import repository as repo
    from app.services import catalogues

    ctx = client.app.state.ctx
    row = catalogues.create(ctx, n=12, seed=2, constraints=["ttc<3"], chunk_size=5)
    with ctx.db.session() as s:
        repo.get_catalogue(s, row.id).status = "running"
    folder = chunkfile.progress_dir(ctx.data_dir, row.id)
    folder.mkdir(parents=True, exist_ok=True)  # the runner's stage file makes it
    chunkfile.write_progress(folder, 1, 3)  # 3 of chunk 1 (idx 5..9) done, none stored
    status = client.get(f"/catalogues/{row.id}").json()
    assert status["scenarios_done"] == 3 and status["scenarios_stored"] == 0
    assert status["progress"] == pytest.approx(3 / 12)
    chunkfile.write_progress(folder, 1, 4)
    assert client.get(f"/catalogues/{row.id}").json()["scenarios_done"] == 4
    # the stage the runner writes beside them is shown while the job runs
    assert client.get(f"/catalogues/{row.id}").json()["stage"] is None
    chunkfile.write_stage(folder, "estimating P(A): pilot (plain Monte Carlo)", 40960, 2000000)
    assert client.get(f"/catalogues/{row.id}").json()["stage"] == {
        "name": "estimating P(A): pilot (plain Monte Carlo)", "done": 40960, "total": 2000000}
    with ctx.db.session() as s:
        repo.get_catalogue(s, row.id).status = "cancelled"
    chunkfile.clear_progress(folder, 1)


def test_wagner_scan_is_opt_in_and_its_fields_are_null_by_default(
        client: Any, catalogue: dict[str, Any]) -> None:
    """Without ``wagner_scan`` a catalogue's rows carry the risks at t_p but null
    alarm_time, risk_peak and risks at the crossing (docs/api.md); the same seed with the
    scan asked for fills them, and changes nothing else of the record."""
    r = client.post("/catalogues", json={"n": 5, "seed": 9, "constraints": ["ttc<3"],
                                         "chunk_size": 5})
    assert r.status_code == 202, r.text
    plain = _finished(client, r.json()["id"])
    assert plain["status"] == "done", plain["error"]
    assert plain["wagner_scan"] is False
    assert plain["summary"].get("risk", {"count": 0})["count"] == 0
    scan_only = {"alarm_time", "risk_peak", "r_dep_cross", "r_ind_cross", "r_dep_cross_r157",
                 "r_ind_cross_r157"}
    rows = client.get(f"/catalogues/{plain['id']}/scenarios",
                      params={"limit": 10, "order_by": "index"}).json()["scenarios"]
    assert len(rows) == 5
    for row in rows:
        assert all(row[k] is None for k in scan_only), row
        assert row["r_dep_tp"] is not None and row["btn"] is not None
    # chunk 0 of both catalogues holds the same vectors (same seed, same chunk size)
    full = client.get(f"/catalogues/{catalogue['id']}/scenarios",
                      params={"limit": 5, "order_by": "index"}).json()["scenarios"]
    for a, b in zip(rows, full, strict=True):
        assert a["params"] == b["params"]
        assert all(b[k] is not None for k in ("risk_peak", "r_dep_cross")), b
        same = set(a) - scan_only - {"id", "exposure_weight", "scenario_id", "catalogue"}
        assert {k: a[k] for k in same} == {k: b[k] for k in same}
