"""Evaluations of a system under test (issue 24, items 9 and 10): the SUT registry, the
stored, resumable campaign job and its routes.

The campaign's runner is injected through the service layer (``ctx.campaign_runner``) so
that these tests check the app's part (storage, resume, paging, filters, export, errors)
with a runner whose outcome is known by hand; ``test_evaluations_e2e.py`` runs the real
simulator end to end."""

from __future__ import annotations

import contextlib
import io
import json
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from app.services import evaluations as service
from app.services import suts
from datasets import PARAM_NAMES
from tests.app.factories import copy_model_cache, make_settings, wait_for


class Outcomes:
    """What the stand-in runner returns: a collision iff the cutter closes faster than
    ``dv_hit`` m/s; impact speed = dv - dv_hit; vs_careful 'worse' on collisions."""

    def __init__(self, params: np.ndarray, dv_hit: float) -> None:
        dv = params[:, PARAM_NAMES.index("dv")]
        self.collided = dv > dv_hit
        self.impact_speed = np.where(self.collided, dv - dv_hit, 0.0)
        self.r_dep_peak = np.clip(dv / 10.0, 0.0, 1.0)
        self.vs_careful = np.where(self.collided, "worse", "same")

    def records(self) -> list[dict[str, Any]]:  # pragma: no cover - the protocol's
        return []


class CountingRunner:
    """A stand-in ``sampler.campaign.Runner`` that counts the rows it simulated."""

    name = "stand-in"

    def __init__(self, dv_hit: float = 6.0) -> None:
        self.dv_hit = dv_hit
        self.rows = 0

    def __call__(self, params: np.ndarray, seeds: np.ndarray) -> Outcomes:
        self.rows += params.shape[0]
        return Outcomes(np.asarray(params), self.dv_hit)


@pytest.fixture(scope="module")
def runner() -> CountingRunner:
    return CountingRunner()


@pytest.fixture(scope="module")
def _models(shared_models: dict[str, Any]) -> dict[str, Any]:
    """The model objects the module's contexts share (``share_models``; not the
    determinism test's): the test process's."""
    return shared_models


@pytest.fixture(scope="module")
def eval_client(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory,
                runner: CountingRunner, _models: dict[str, Any]) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    from tests.app.factories import make_app, share_models

    data_dir = tmp_path_factory.mktemp("evaluations")
    copy_model_cache(model_cache_dir, data_dir)
    app = make_app(make_settings(data_dir))
    start = pytest.MonkeyPatch()
    share_models(start, _models)  # for the app's start only
    try:
        with TestClient(app) as client:
            start.undo()
            client.app.state.ctx.campaign_runner = lambda factory, settings: runner
            yield client
    finally:
        start.undo()


def _done(client: Any, eid: str) -> dict[str, Any]:
    def finished() -> bool:
        return client.get(f"/evaluations/{eid}").json()["status"] in ("done", "failed",
                                                                      "cancelled")
    wait_for(finished, f"evaluation {eid}")
    body: dict[str, Any] = client.get(f"/evaluations/{eid}").json()
    return body


# --------------------------------------------------------------------------- registry
def test_registry_lists_the_builtins_with_their_sources() -> None:
    reg = suts.registry()
    for name in ("none", "r157_cc", "rss", "idm", "acc", "acc_aeb"):
        assert reg.entries[name].origin == "builtin"
    assert reg.entries["acc"].source  # a citation, not empty


def test_a_module_path_is_refused_over_http_naming_the_field(eval_client: Any) -> None:
    r = eval_client.post("/evaluations", json={"sut": "os.path:join", "n": 10})
    assert r.status_code == 422
    err = r.json()["error"]
    assert err["field"] == "body.sut"
    assert "module path" in err["message"] and "registered" in err["message"]
    r = eval_client.post("/evaluations", json={"sut": "no_such_sut", "n": 10})
    assert r.status_code == 422 and r.json()["error"]["field"] == "body.sut"
    assert "unknown system under test" in r.json()["error"]["message"]


def test_bad_numbers_name_their_field(eval_client: Any) -> None:
    for body, field in (({"sut": "acc", "n": 0}, "body.n"),
                        ({"sut": "acc", "rhw": 0}, "body.rhw"),
                        ({"sut": "acc", "sut_params": {"nope": 1}}, "body.sut_params"),
                        ({"sut": "acc", "constraints": ["ttc<<3"]}, "body.constraints.0"),
                        ({"sut": "acc", "wat": 1}, "body.wat")):
        r = eval_client.post("/evaluations", json=body)
        assert r.status_code == 422, body
        assert r.json()["error"]["field"] == field, (body, r.json())


def test_a_bad_request_is_422_even_over_the_quota(eval_client: Any) -> None:
    """A client with a job queued sent a request with a bad constraint and was told to
    wait (429 naming body.n, which it had not given) instead of what was wrong; a request
    without n counts its max_runs, and the 429 now says so and names body.max_runs."""
    settings = eval_client.app.state.ctx.settings
    quotas = eval_client.app.state.jobs.quotas
    token = quotas.admit("testclient", settings.client_queued_scenarios_limit - 100, settings)
    try:
        r = eval_client.post("/evaluations", json={"sut": "acc", "n": 500,
                                                   "constraints": ["foo<3"]})
        assert r.status_code == 422 and r.json()["error"]["field"] == "body.constraints.0"
        r = eval_client.post("/evaluations", json={"sut": "acc", "n": 500,
                                                   "sut_params": {"nope": 1}})
        assert r.status_code == 422 and r.json()["error"]["field"] == "body.sut_params"
        r = eval_client.post("/evaluations", json={"sut": "acc"})  # the stop rule
        assert r.status_code == 429
        err = r.json()["error"]
        assert err["field"] == "body.max_runs"
        assert "without n an evaluation counts its max_runs" in err["message"]
        r = eval_client.post("/evaluations", json={"sut": "acc", "n": 500})
        assert r.status_code == 429 and r.json()["error"]["field"] == "body.n"
    finally:
        quotas.release(token)


def test_suts_route_lists_what_the_registry_holds(eval_client: Any) -> None:
    body = eval_client.get("/suts").json()
    names = [s["name"] for s in body["suts"]]
    assert names[:2] == ["none", "r157_cc"]
    assert "acc" in names


# --------------------------------------------------------------------------- job
@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_an_evaluation_runs_stores_its_runs_and_pages_them(eval_client: Any) -> None:
    r = eval_client.post("/evaluations", json={"sut": "acc", "n": 3000, "batch_size": 1000,
                                               "seed": 3})
    assert r.status_code == 202
    eid = r.json()["id"]
    assert r.json()["href"] == f"/evaluations/{eid}"
    st = _done(eval_client, eid)
    assert st["status"] == "done", st["error"]
    assert st["runs_done"] == 3000 and st["chunks_done"] == 3 and st["progress"] == 1.0
    summary = st["summary"]
    assert summary["runs"] == 3000
    # every collided run is stored and the count matches the summary's
    page = eval_client.get(f"/evaluations/{eid}/runs",
                           params={"collided": "true", "limit": 1000}).json()
    assert page["total"] == summary["collisions"] == st["collisions_so_far"]
    assert page["total"] > 0
    runs = page["runs"]
    # hand rule of the stand-in: collided iff dv > 6, impact speed dv - 6
    for rec in runs:
        assert rec["dv"] > 6.0
        assert rec["impact_speed"] == pytest.approx(rec["dv"] - 6.0, abs=1e-12)
        assert rec["vs_careful"] == "worse"
    speeds = [rec["impact_speed"] for rec in runs]
    assert speeds == sorted(speeds, reverse=True)  # default order: impact speed, desc
    # the estimate is the mean of the weights of the collided runs: sum(w_i c_i) / N
    # (weight = w / P(B) once done)
    if len(runs) == page["total"]:
        est = sum(rec["weight"] for rec in runs) / summary["runs"]
        assert est == pytest.approx(summary["p_collision"]["estimate"], rel=1e-9)
    # filters and order
    low = eval_client.get(f"/evaluations/{eid}/runs",
                          params={"impact_speed_max": 0.5, "collided": "true",
                                  "order_by": "impact_speed", "desc": "false"}).json()
    assert all(0 <= rec["impact_speed"] <= 0.5 for rec in low["runs"])
    same = eval_client.get(f"/evaluations/{eid}/runs",
                           params={"vs_careful": "same", "limit": 5}).json()
    assert same["total"] == st["runs_simulated"] - summary["collisions"]
    by_run = eval_client.get(f"/evaluations/{eid}/runs",
                             params={"order_by": "run", "limit": 50}).json()["runs"]
    assert [rec["run"] for rec in by_run] == sorted(rec["run"] for rec in by_run)


def test_runs_filters_refuse_unknown_names(eval_client: Any) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "none", "n": 10}).json()["id"]
    r = eval_client.get(f"/evaluations/{eid}/runs", params={"speed_min": 1})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.speed_min"
    r = eval_client.get(f"/evaluations/{eid}/runs", params={"order_by": "nope"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.order_by"
    r = eval_client.get(f"/evaluations/{eid}/runs", params={"vs_careful": "meh"})
    assert r.status_code == 422 and r.json()["error"]["field"].startswith("query.vs_careful")
    assert eval_client.get("/evaluations/eval-nope").status_code == 404


def test_export_of_the_failing_runs(eval_client: Any) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 1000,
                                                 "seed": 5}).json()["id"]
    st = _done(eval_client, eid)
    r = eval_client.get(f"/evaluations/{eid}/export", params={"format": "json"})
    assert r.status_code == 200
    doc = json.loads(r.content)
    assert doc["format"] == "scengen.evaluation-failures/1"
    assert 0 < len(doc["runs"]) <= st["summary"]["collisions"]
    first = doc["runs"][0]
    assert first["run"]["collided"] is True
    assert first["scenario"]["schema"] == "scengen.concrete-scenario/1"
    r = eval_client.get(f"/evaluations/{eid}/export", params={"format": "xosc"})
    assert r.status_code == 200 and r.content[:2] == b"PK"
    r = eval_client.get(f"/evaluations/{eid}/export", params={"format": "csv"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "query.format"


def test_export_takes_the_filters_of_runs(eval_client: Any) -> None:
    """The export used to ignore its query besides ``format``: ``vs_careful=same`` answered
    the collided runs (every one 'worse' under the stand-in's rule)."""
    eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 1000,
                                                 "seed": 7}).json()["id"]
    _done(eval_client, eid)
    for params in ({"vs_careful": "same"},
                   {"vs_careful": "worse", "impact_speed_max": 0.5}):
        listed = eval_client.get(f"/evaluations/{eid}/runs",
                                 params={**params, "limit": 1000}).json()
        assert listed["total"] > 0
        r = eval_client.get(f"/evaluations/{eid}/export", params={**params, "format": "json"})
        assert r.status_code == 200
        runs = [item["run"] for item in json.loads(r.content)["runs"]]
        # each exported run is one /runs lists (a vector the builder refuses is left out)
        assert 0 < len(runs) <= listed["total"]
        assert {rec["run"] for rec in runs} <= {rec["run"] for rec in listed["runs"]}
        for rec in runs:  # the stand-in's hand rule: worse iff collided iff dv > 6
            assert rec["vs_careful"] == params["vs_careful"]
            assert rec["collided"] is (params["vs_careful"] == "worse")
            if "impact_speed_max" in params:
                assert rec["impact_speed"] <= 0.5
    # no filter: the failing runs, as before
    doc = json.loads(eval_client.get(f"/evaluations/{eid}/export").content)
    assert doc["runs"] and all(item["run"]["collided"] is True for item in doc["runs"])


@pytest.mark.parametrize("route", ["runs", "export"])
def test_unknown_query_parameters_are_named(eval_client: Any, route: str) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "none", "n": 10}).json()["id"]
    r = eval_client.get(f"/evaluations/{eid}/{route}", params={"vs_carful": "worse"})
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["field"] == "query.vs_carful" and "vs_carful" in err["message"]
    r = eval_client.get(f"/evaluations/{eid}/{route}", params={"impact_speed_max": "inf"})
    assert r.status_code == 422 and "impact_speed_max" in r.text
    r = eval_client.get(f"/evaluations/{eid}/{route}", params={"impact_speed_max": "１"})
    assert r.status_code == 422 and "impact_speed_max" in r.text


def test_openapi_declares_the_run_filters(eval_client: Any) -> None:
    paths = eval_client.get("/openapi.json").json()["paths"]
    names = ([f"{f}_{b}" for f in ("impact_speed", "r_dep_peak", "min_gap", "min_ttc")
              for b in ("min", "max")] + ["collided", "must_avoid", "violation", "vs_careful"])
    for path in ("/evaluations/{evaluation_id}/runs", "/evaluations/{evaluation_id}/export"):
        declared = {p["name"]: p for p in paths[path]["get"]["parameters"]
                    if p["in"] == "query"}
        assert set(names) <= set(declared), (path, sorted(declared))
        assert declared["impact_speed_min"]["schema"]["anyOf"][0]["type"] == "number"
        assert declared["collided"]["schema"]["anyOf"][0]["type"] == "boolean"
        items = declared["vs_careful"]["schema"]["anyOf"][0]["items"]
        assert items["enum"] == ["worse", "same", "better"]
        # must_avoid is the regulation's TTC formula (docs/systems.md), not what the
        # careful driver does (the description said "the cut-in is one the R157 careful
        # driver avoids")
        text = declared["must_avoid"].get("description", "")
        assert "5.2.5.2" in text and "careful" not in text, text


class NoRiskRunner(CountingRunner):
    """The simulator's outcome without ``risk``: the TTR-risk fields are NaN."""

    def __call__(self, params: np.ndarray, seeds: np.ndarray) -> Outcomes:
        out = super().__call__(params, seeds)
        out.r_dep_peak = np.full(len(out.collided), np.nan)
        return out


def test_risk_fields_not_computed_are_null(eval_client: Any) -> None:
    """docs/api.md: null means "no value"; without ``risk`` the runs said "NaN" (seen by
    a new user in /runs and the JSON export), though the docs promise null."""
    ctx = eval_client.app.state.ctx
    before = ctx.campaign_runner
    ctx.campaign_runner = lambda factory, settings: NoRiskRunner()
    try:
        eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 200,
                                                     "seed": 3}).json()["id"]
        st = _done(eval_client, eid)
    finally:
        ctx.campaign_runner = before
    assert st["status"] == "done", st["error"]
    runs = eval_client.get(f"/evaluations/{eid}/runs", params={"limit": 50}).json()["runs"]
    assert runs and all(r["r_dep_peak"] is None for r in runs)
    assert "NaN" not in json.dumps([r["r_dep_peak"] for r in runs])
    doc = json.loads(eval_client.get(f"/evaluations/{eid}/export",
                                     params={"format": "json"}).content)
    assert doc["runs"] and all(x["run"]["r_dep_peak"] is None for x in doc["runs"])


def test_delete_cancels_and_removes(eval_client: Any) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 500}).json()["id"]
    assert eval_client.delete(f"/evaluations/{eid}").status_code == 204
    assert eval_client.get(f"/evaluations/{eid}").status_code == 404
    assert eval_client.delete(f"/evaluations/{eid}").status_code == 404


# --------------------------------------------------------------------------- resume
@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_an_interrupted_job_resumes_from_its_stored_chunks(
        model_cache_dir: Path, tmp_path: Path, database_url: str, shared_model: None) -> None:
    """Stop after 2 of 5 chunks, resume: the stored chunks are replayed, not simulated
    again, and the result equals an uninterrupted run's, bit for bit (SQLite and
    PostgreSQL); the runs' filters and order work on both."""
    from app.services.store import open_context

    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    ctx = open_context(make_settings(data_dir, database_url=database_url))
    try:
        runner = CountingRunner()
        ctx.campaign_runner = lambda factory, settings: runner
        spec = {"sut": "acc", "n": 2500, "batch_size": 500, "seed": 11}
        a = service.create(ctx, **spec).id
        b = service.create(ctx, **spec).id
        assert service.run_job(ctx, a) == "done"
        rows_a = runner.rows

        stop = threading.Event()

        def progress(stage: str, done: int, total: int) -> None:
            if done >= 1000:
                stop.set()

        runner.rows = 0
        assert service.run_job(ctx, b, stop=stop, progress=progress) == "interrupted"
        assert service.describe(ctx, b).chunks_done == 2
        simulated_before = runner.rows
        runner.rows = 0
        assert service.run_job(ctx, b) == "done"
        # the resumed run simulated only chunks 2..4: together, what run a simulated
        assert runner.rows + simulated_before == rows_a
        assert simulated_before > 0 and 0 < runner.rows < rows_a
        sa, sb = service.describe(ctx, a).summary, service.describe(ctx, b).summary
        assert sa == sb
        ta, ra = service.page_runs(ctx, a, service.RunFilter(), 0, 10_000, order_by="run",
                                   desc=False)
        tb, rb = service.page_runs(ctx, b, service.RunFilter(), 0, 10_000, order_by="run",
                                   desc=False)
        assert ta == tb == len(ra) and ra == rb
        # filters in SQL against the same filter in Python on every run
        flt = service.run_filter([("impact_speed_min", "0.5"), ("collided", "true")])
        total, got = service.page_runs(ctx, b, flt, 0, 1000, order_by="impact_speed",
                                       desc=True)
        want = sorted((r for r in rb if r["collided"] and r["impact_speed"] >= 0.5),
                      key=lambda r: (-r["impact_speed"], r["run"]))
        assert total == len(want) and [r["run"] for r in got] == [r["run"] for r in want]
    finally:
        ctx.close()


# --------------------------------------------------------------------------- CLI
class OneRunBrake:
    """A per-run SUT for the ``--sut module:Class`` path: brakes at 3 m/s² always."""

    def reset(self, seed: int) -> None:
        self.seed = seed

    def act(self, obs: Any) -> float:
        return -3.0


class DeclaredGap(OneRunBrake):
    """A user's class that declares its parameters and compares them as numbers (as
    examples/sut-package's GapKeeper does)."""

    parameters: ClassVar[dict[str, tuple[float, str, str]]] = {
        "time_gap": (1.0, "s", "the gap it keeps")}

    def __init__(self, time_gap: float = 1.0) -> None:
        if not time_gap > 0:
            raise ValueError("time_gap > 0 please")


def _cli_runner(monkeypatch: pytest.MonkeyPatch) -> CountingRunner:
    runner = CountingRunner()
    made: list[Any] = []

    def maker(factory: Any, settings: Any) -> CountingRunner:
        made.append(factory)
        return runner

    monkeypatch.setattr(service, "default_runner", maker)
    runner.made = made  # type: ignore[attr-defined]
    return runner


@pytest.fixture
def cli_runner(monkeypatch: pytest.MonkeyPatch) -> CountingRunner:
    return _cli_runner(monkeypatch)


@pytest.fixture
def shared_model(monkeypatch: pytest.MonkeyPatch, _models: dict[str, Any]) -> None:
    """The test's contexts keep the module's default model object (of ``eval_client``, of
    the shared campaign or of the first test to run): its memo is not estimated again
    (``share_models``)."""
    from tests.app.factories import share_models

    share_models(monkeypatch, _models)


#: the CLI campaign that three tests below read (made once: each costs seconds)
ACC_ARGV = ["evaluate", "--sut", "acc", "-n", "1500", "--seed", "4", "--batch-size", "500"]


@dataclass(frozen=True)
class CliRun:
    code: int
    out: str
    err: str
    runs: str  # the --runs file's text


@pytest.fixture(scope="module")
def acc_cli_run(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory,
                _models: dict[str, Any]) -> CliRun:
    """``scengen evaluate`` ``ACC_ARGV --runs FILE`` on a private store with the stand-in
    runner (as the fixtures ``store`` and ``cli_runner``): its exit code, stdout, stderr
    and runs file. Its model object is the one ``shared_model`` gives the tests that ask
    for it."""
    from app.cli import main
    from tests.app.factories import cli_store, share_models

    tmp = tmp_path_factory.mktemp("cli-evaluate")
    runs = tmp / "runs.jsonl"
    out, err = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as mp, cli_store(tmp / "data", model_cache_dir, mp):
        _cli_runner(mp)
        share_models(mp, _models)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main([*ACC_ARGV, "--runs", str(runs)])
    return CliRun(code, out.getvalue(), err.getvalue(), runs.read_text())


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_cli_evaluate_prints_the_summary_and_writes_every_run(acc_cli_run: CliRun) -> None:
    assert acc_cli_run.code == 0
    summary = json.loads(acc_cli_run.out)
    assert list(summary)[:7] == ["sut", "p_collision", "rate_per_hour", "runs",
                                 "collisions", "ess", "acceleration"]
    assert summary["sut"] == "acc" and summary["runs"] == 1500
    for key in ("estimate", "ci", "model_ci"):
        assert key in summary["p_collision"] and key in summary["rate_per_hour"]
    lines = [json.loads(x) for x in acc_cli_run.runs.splitlines()]
    assert len(lines) == 1500
    # seeds as strings (as /runs gives them): a uint64 does not survive jq 1.6 or JS
    assert all(isinstance(x["seed"], str) and 0 <= int(x["seed"]) < 2**64 for x in lines)
    assert any(int(x["seed"]) > 2**53 for x in lines)
    hits = [x for x in lines if x["collided"]]
    assert len(hits) == summary["collisions"] > 0
    for x in hits:  # the stand-in's rule, by hand
        assert x["dv"] > 6.0 and x["simulated"] is True
    est = sum(x["weight"] for x in hits) / len(lines)
    assert est == pytest.approx(summary["p_collision"]["estimate"], rel=1e-9)
    assert "draws" in acc_cli_run.err  # the progress bar
    # it starts before any draw is simulated, so its rate is draws per second of the
    # campaign: it once appeared only when done and said "171196081.63run/s"
    rates = [float(r) for r in re.findall(r"([0-9.]+)run/s", acc_cli_run.err)]
    assert rates and max(rates) < 1e7


def test_cli_evaluate_stop_rule_bar_shows_no_time_to_max_runs(
        store: Path, cli_runner: CountingRunner, capsys: pytest.CaptureFixture[str],
        shared_model: None) -> None:
    """With the stop rule the bar's total is max_runs; tqdm's time remaining to it (an
    hour for a campaign that stopped after minutes) is left out, the rule is said."""
    from app.cli import main

    assert main(["evaluate", "--sut", "acc", "--rhw", "0.3", "--max-runs", "400",
                 "--batch-size", "200", "--seed", "3"]) == 0
    err = capsys.readouterr().err
    assert "of at most 400" in err and "until the 95 % interval is within ±0.3" in err
    assert not re.search(r"<\d+:\d+", err), err  # tqdm's "[elapsed<remaining, rate]"


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_cli_evaluate_is_deterministic(store: Path, tmp_path: Path, cli_runner: CountingRunner,
                                       capsys: pytest.CaptureFixture[str],
                                       acc_cli_run: CliRun) -> None:
    """The shared campaign again, on another store with the same model and quiet: the
    same stdout and the same runs file, byte for byte."""
    from app.cli import main

    runs = tmp_path / "again.jsonl"
    assert main([*ACC_ARGV, "-q", "--runs", str(runs)]) == 0
    out = capsys.readouterr()
    assert out.out == acc_cli_run.out
    assert runs.read_text() == acc_cli_run.runs
    assert out.err == ""  # -q: no progress bar


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_cli_evaluate_takes_a_module_path(store: Path, cli_runner: CountingRunner,
                                         capsys: pytest.CaptureFixture[str],
                                         shared_model: None) -> None:
    from app.cli import main

    assert main(["evaluate", "--sut", "tests.app.test_evaluations:OneRunBrake", "-n", "300",
                 "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sut"] == "tests.app.test_evaluations:OneRunBrake"
    sut = cli_runner.made[0]()  # type: ignore[attr-defined]
    assert sut.name == "tests.app.test_evaluations:OneRunBrake"  # wrapped by per_run


@pytest.mark.parametrize("argv, needle", [
    (["--sut", "no_such"], "unknown system under test"),
    (["--sut", "acc", "-n", "0"], "--n"),
    (["--sut", "acc", "--rhw", "-1"], "--rhw"),
    # the CLI's option is named, not the request's key (was "sut_params: ...")
    (["--sut", "acc", "--sut-param", "nope=1"], "--sut-param: acc refuses them"),
    # a module is not a SUT: the reference is named, not the parameters (was "sut_params")
    (["--sut", "os:path"], "--sut: 'os:path' is a module"),
    # 0 is refused, not taken for the default (was silently 2000 / 200000)
    (["--sut", "acc", "-n", "5", "--batch-size", "0"], "--batch-size"),
    (["--sut", "acc", "--max-runs", "0"], "--max-runs"),
    (["--sut", "acc", "--setting", "dt=0"], "--setting: dt"),
    # a declared numeric parameter given a word: said so, not the class's TypeError
    # ("'>' not supported between instances of 'str' and 'int'")
    (["--sut", "tests.app.test_evaluations:DeclaredGap", "--sut-param", "time_gap=abc"],
     "--sut-param: tests.app.test_evaluations:DeclaredGap.time_gap: expected a number, "
     "got 'abc'"),
    (["--sut", "acc", "--sut-param", "novalue"], "KEY=VALUE"),
    (["--sut", "nomodule_xyz:Thing"], "cannot import"),
    (["-n", "5"], "--sut"),
    (["--sut", "acc", "-n", "5", "--rhw", "0.3"], "not allowed with"),
    (["--sut", "acc", "-c", "ttc<<3"], "ttc<<3"),
])
def test_cli_evaluate_bad_input_is_one_line(store: Path, cli_runner: CountingRunner,
                                            capsys: pytest.CaptureFixture[str],
                                            argv: list[str], needle: str) -> None:
    from app.cli import main

    with pytest.raises(SystemExit) if "--rhw" in argv and "-n" in argv else _nothing():
        code = main(["evaluate", "-q", *argv])
        assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert needle in err


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: Any) -> bool:
        return False


# --------------------------------------------------------------------------- by weight
#: the hand-built campaign: chunk 0 a pilot chunk (counted False), chunk 1 counted;
#: (weight_raw = p/q, collided, impact speed [m/s], simulated) per draw
HAND_CHUNKS = (
    (False, ((0.9, True, 1.0, True), (0.2, True, 3.0, True), (0.05, False, 0.0, True))),
    (True, ((0.01, True, 40.0, True), (0.3, True, 2.0, True), (0.06, True, 5.0, True),
            (0.5, False, 0.0, True), (0.7, False, 0.0, False))),
)
HAND_BATCH = 5  # chunk k's runs start at 5 k
HAND_PB = 0.5  # the summary's P(B): weight = weight_raw / P(B)


def _hand_built_evaluation(ctx: Any, *, done: bool) -> str:
    """An evaluation whose chunks and runs are the hand-made ``HAND_CHUNKS`` (no
    simulator): the weights, hence the order and the shares, are known by hand."""
    from app import jsonconv
    from app.db.models import EvaluationRow
    from sampler.campaign import ChunkResult

    eid = service.create(ctx, sut="acc", n=10, batch_size=HAND_BATCH, seed=0).id
    model = ctx.model(service.describe(ctx, eid).model)
    draws = 0
    for k, (counted, runs) in enumerate(HAND_CHUNKS):
        n = len(runs)
        z = np.linspace(-0.5, 0.5, n)[:, None] * np.ones((1, model.n_features))
        w = np.array([r[0] for r in runs])
        chunk = ChunkResult(
            index=k, params=model.params_matrix(model.from_z(z)), z=z,
            seeds=np.arange(n, dtype=np.uint64), part=np.zeros(n, dtype=np.int64),
            log_p=np.log(w), log_q=np.zeros(n), weights=w,
            simulated=np.array([r[3] for r in runs]),
            outcome={"collided": np.array([r[1] for r in runs]),
                     "impact_speed": np.array([r[2] for r in runs])},
            counted=counted)
        assert service.store_chunk(ctx, eid, chunk, HAND_BATCH)
        draws += n
    if done:
        pilot = sum(len(runs) for counted, runs in HAND_CHUNKS if not counted)
        with ctx.db.session() as s:
            row = s.get(EvaluationRow, eid)
            row.status = "done"
            row.summary = jsonconv.encode({"p_bounds": HAND_PB, "runs": draws,
                                           "pilot_runs": pilot, "collisions": 3})
    return eid


def test_runs_by_weight_and_the_failures_that_carry_p(eval_client: Any) -> None:
    """``order_by=weight`` and the dashboard's failures list on a hand-built campaign: the
    counted collided runs have weights_raw 0.01 (impact 40 m/s: first by impact speed),
    0.3 and 0.06, the pilot ones 0.9 and 0.2; P(B) = 0.5."""
    ctx = eval_client.app.state.ctx
    eid = _hand_built_evaluation(ctx, done=True)
    # run index = chunk * 5 + position: chunk 0's are 0-2, chunk 1's 5-9 (9 not simulated)
    page = eval_client.get(f"/evaluations/{eid}/runs",
                           params={"order_by": "weight", "collided": "true"}).json()
    assert [r["run"] for r in page["runs"]] == [0, 6, 1, 7, 5]  # 0.9, 0.3, 0.2, 0.06, 0.01
    assert [r["weight"] for r in page["runs"]] == pytest.approx([1.8, 0.6, 0.4, 0.12, 0.02])
    every = eval_client.get(f"/evaluations/{eid}/runs", params={"order_by": "weight"}).json()
    assert [r["run"] for r in every["runs"]] == [0, 8, 6, 1, 7, 2, 5]  # 9: not simulated
    up = eval_client.get(f"/evaluations/{eid}/runs",
                         params={"order_by": "weight", "desc": "false", "limit": 2}).json()
    assert [r["run"] for r in up["runs"]] == [5, 2]
    # the dashboard: the counted collided runs by weight, then the pilot ones
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["failures_total"] == 5 and view["failures_pilot"] == 2
    rows = view["failures"]
    assert [r["run"] for r in rows] == [6, 7, 5, 0, 1]
    assert [r["counted"] for r in rows] == [True, True, True, False, False]
    counted_sum = 0.01 + 0.3 + 0.06  # P(B) cancels: weight / sum = weight_raw / sum
    assert rows[0]["share"] == pytest.approx(0.3 / counted_sum, rel=1e-12)  # 0.8108...
    assert rows[1]["share"] == pytest.approx(0.06 / counted_sum, rel=1e-12)
    assert rows[2]["share"] == pytest.approx(0.01 / counted_sum, rel=1e-12)
    assert rows[3]["share"] is None and rows[4]["share"] is None


def test_failures_before_done_have_no_share(eval_client: Any) -> None:
    """Until the evaluation is done (no P(B), no pilot_runs) every collided run is listed
    by weight_raw and no share is given."""
    eid = _hand_built_evaluation(eval_client.app.state.ctx, done=False)
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["failures_total"] == 5 and view["failures_pilot"] == 0
    assert [r["run"] for r in view["failures"]] == [0, 6, 1, 7, 5]
    assert all(r["share"] is None and r["weight"] is None for r in view["failures"])


@pytest.mark.parametrize("key", ["weight_raw", "Weight", "-weight", "share"])
def test_a_bad_order_key_is_named(eval_client: Any, key: str) -> None:
    eid = _hand_built_evaluation(eval_client.app.state.ctx, done=True)
    r = eval_client.get(f"/evaluations/{eid}/runs", params={"order_by": key})
    assert r.status_code == 422
    err = r.json()["error"]
    assert err["field"] == "query.order_by" and "weight" in err["message"]


# --------------------------------------------------------------------------- dashboard
def test_dashboard_views_of_an_evaluation(eval_client: Any) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 600,
                                                 "seed": 2}).json()["id"]
    st = _done(eval_client, eid)
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["evaluation"]["sut"] == "acc"
    assert view["figures"]["collisions"] == st["summary"]["collisions"]
    assert view["failures_total"] == st["summary"]["collisions"]
    # the runs that carry most of P first; the shares of all counted collided runs add up
    # to 1 and make P: sum(weight) / counted draws (the summary's runs - pilot_runs)
    # (the pilot ones of the cross-entropy campaign after them); a run's share is its
    # weight over the sum of the counted collided runs' weights, which is P times the
    # counted draws (the summary's runs - pilot_runs; no region: P(A) = 1)
    rows = view["failures"]
    counted = [r for r in rows if r["counted"]]
    assert rows[:len(counted)] == counted
    if len(rows) == view["failures_total"]:  # all shown
        assert len(rows) - len(counted) == view["failures_pilot"]
    for part in (counted, rows[len(counted):]):
        weights = [r["weight"] for r in part]
        assert weights == sorted(weights, reverse=True)
    summary = st["summary"]
    whole = summary["p_collision"]["estimate"] * (summary["runs"] - summary["pilot_runs"])
    assert counted and [r["share"] for r in counted] == pytest.approx(
        [r["weight"] / whole for r in counted], rel=1e-9)
    assert all(r["share"] is None for r in rows[len(counted):])
    sc = view["scatter"]
    n_shown = min(400, st["runs_simulated"])
    assert len(sc["run"]) == len(sc["btn"]) == len(sc["r_dep_peak"]) == n_shown
    assert sum(sc["collided"]) == min(n_shown, st["summary"]["collisions"])
    assert view["careful"] is None  # no r157_cc evaluation on this model and region yet
    # one run driven again by the SUT and by the careful driver (the real simulator)
    run = view["failures"][0]["run"]
    prof = eval_client.get(f"/dashboard/api/evaluations/{eid}/runs/{run}").json()
    assert prof["run"]["run"] == run
    for who in ("sut", "careful"):
        d = prof["drivers"][who]
        assert len(d["t"]) == len(d["v"]) == len(d["a"]) > 10
        assert d["t"][0] == 0.0
    # both start at the scenario's ego speed
    assert prof["drivers"]["sut"]["v"][0] == pytest.approx(prof["drivers"]["careful"]["v"][0])
    r = eval_client.get(f"/dashboard/api/evaluations/{eid}/runs/99999999")
    assert r.status_code == 404 and r.json()["error"]["field"] == "path.run"
    page = eval_client.get("/dashboard")
    assert page.status_code == 200 and "view-sut" in page.text
    assert eval_client.get("/dashboard/static/dashboard_sut.js").status_code == 200


def test_the_dashboard_says_how_to_get_the_careful_drivers_rate(eval_client: Any) -> None:
    """Without a careful evaluation on the model and region, the view gives the request
    that makes one; a queued one is shown with its progress, a finished one with its
    figures."""
    ctx = eval_client.app.state.ctx
    eid = eval_client.post("/evaluations", json={
        "sut": "acc", "n": 50, "seed": 3, "constraints": ["v_ego>25"],
        "settings": {"dt": 0.02}}).json()["id"]
    _done(eval_client, eid)
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    model = view["evaluation"]["model"]
    assert view["careful"] is None
    req = view["careful_request"]
    assert req == {"sut": "r157_cc", "model": model, "constraints": ["v_ego>25"], "seed": 3,
                   "n": 50, "settings": {"dt": 0.02}}
    row = service.create(ctx, **req)  # stored, not yet run
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["careful"] == {"id": row.id, "status": "queued", "figures": None,
                               "runs_done": 0, "runs_planned": 50}
    assert service.run_job(ctx, row.id) == "done"
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    careful = eval_client.get(f"/evaluations/{row.id}").json()
    assert view["careful"]["id"] == row.id and view["careful"]["status"] == "done"
    assert view["careful"]["figures"]["collisions"] == careful["summary"]["collisions"]
    assert view["careful"]["figures"]["runs"] == careful["summary"]["runs"]
    # the stop rule's request when the SUT's evaluation used it
    eid2 = eval_client.post("/evaluations", json={
        "sut": "acc", "rhw": 0.5, "max_runs": 40, "seed": 4,
        "constraints": ["v_ego>26"]}).json()["id"]
    _done(eval_client, eid2)
    req2 = eval_client.get(f"/dashboard/api/evaluations/{eid2}").json()["careful_request"]
    assert req2 == {"sut": "r157_cc", "model": model, "constraints": ["v_ego>26"], "seed": 4,
                    "rhw": 0.5, "max_runs": 40}


def test_the_careful_drivers_rate_is_one_under_the_same_simulator_settings(
        eval_client: Any) -> None:
    """The careful driver's figures shown beside a SUT's come from an evaluation with the
    same simulator settings (a perception delay or a coarser step changes its rate): one
    under other settings is not shown, and the view offers the request that makes it."""
    ctx = eval_client.app.state.ctx
    settings = {"perception_delay": 0.3}
    eid = eval_client.post("/evaluations", json={
        "sut": "acc", "n": 40, "seed": 6, "constraints": ["v_ego>27"],
        "settings": settings}).json()["id"]
    _done(eval_client, eid)
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    model = view["evaluation"]["model"]
    other = service.create(ctx, sut="r157_cc", model=model, constraints=["v_ego>27"],
                           seed=6, n=40)  # default settings
    assert service.run_job(ctx, other.id) == "done"
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["careful"] is None
    assert view["careful_request"]["settings"] == settings
    same = service.create(ctx, **view["careful_request"])
    assert service.run_job(ctx, same.id) == "done"
    view = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()
    assert view["careful"]["id"] == same.id
    # and a SUT evaluation with the default settings (dt 0.01 given explicitly is the
    # default) is shown beside the default-settings one
    eid2 = eval_client.post("/evaluations", json={
        "sut": "acc", "n": 40, "seed": 6, "constraints": ["v_ego>27"],
        "settings": {"dt": 0.01}}).json()["id"]
    _done(eval_client, eid2)
    assert eval_client.get(f"/dashboard/api/evaluations/{eid2}").json()[
        "careful"]["id"] == other.id


@pytest.mark.parametrize(("collisions", "ess", "flagged"), [
    (0, 0.0, None),                      # no collision: the page shows the upper bound
    (82, 30.5, None),                    # enough of both
    (10, 10.0, None),                    # on the thresholds: trusted
    (9, 40.0, "only 9 collisions"),
    (1, 1.0, "only 1 collision and ESS 1"),
    (300, 1.56, "ESS 1.56"),             # many collisions, two weights dominate
    (50, None, "ESS undefined"),
])
def test_small_evaluations_are_flagged_unreliable(collisions: int, ess: float | None,
                                                  flagged: str | None) -> None:
    from app.dashboard.evaluation_views import reliability

    got = reliability(collisions, ess)
    if flagged is None:
        assert got is None
    else:
        assert got is not None and got.startswith("unreliable: " + flagged + " (")
        # the rule as it is, not "fewer than 10 collisions or ..." beside 300 collisions
        assert "(the intervals need at least 10 collisions and an ESS of at least 10)" in got
        assert "run more" in got


def test_the_dashboard_view_carries_the_reliability_flag(eval_client: Any) -> None:
    eid = eval_client.post("/evaluations", json={"sut": "acc", "n": 300,
                                                 "seed": 5}).json()["id"]
    st = _done(eval_client, eid)["summary"]
    fig = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()["figures"]
    assert fig["sut_runs"] == st["sut_runs"] and fig["runs"] == 300
    few = 0 < st["collisions"] < 10 or (st["collisions"] > 0 and st["ess"] < 10)
    assert (fig["unreliable"] is not None) == few


# --------------------------------------------------------------------------- warnings
def test_the_api_summary_carries_the_warnings(eval_client: Any) -> None:
    """A campaign without any collision (a runner that never collides) stopped at
    max_runs: the summary says it is not reliable, and why, in the HTTP answer; an
    evaluation stored before the fields existed gets them when read."""
    from app.db.models import EvaluationRow

    ctx = eval_client.app.state.ctx
    before = ctx.campaign_runner
    ctx.campaign_runner = lambda factory, settings: CountingRunner(dv_hit=1e9)
    try:
        eid = eval_client.post("/evaluations", json={
            "sut": "acc", "rhw": 0.3, "max_runs": 400, "batch_size": 200,
            "seed": 7}).json()["id"]
        st = _done(eval_client, eid)
    finally:
        ctx.campaign_runner = before
    assert st["status"] == "done", st["error"]
    summary = st["summary"]
    assert summary["collisions"] == 0 and summary["stop_reason"] == "max_runs"
    assert summary["reliable"] is False
    assert len(summary["warnings"]) == 2
    assert summary["warnings"][0].startswith("no collision in 400 draws")
    assert summary["warnings"][1].startswith("stopped at max_runs (400 draws)")
    # the dashboard's figures carry the same list (its flag stays for 1-9 collisions)
    fig = eval_client.get(f"/dashboard/api/evaluations/{eid}").json()["figures"]
    assert fig["warnings"] == summary["warnings"] and fig["unreliable"] is None
    # stored before the change: no warnings, no reliable in the row
    with ctx.db.session() as s:
        row = s.get(EvaluationRow, eid)
        row.summary = {k: v for k, v in row.summary.items()
                       if k not in ("warnings", "reliable")}
    with ctx.db.read_session() as s:
        assert "warnings" not in s.get(EvaluationRow, eid).summary
    again = eval_client.get(f"/evaluations/{eid}")
    assert again.status_code == 200
    assert again.json()["summary"] == summary
    export = eval_client.get(f"/evaluations/{eid}/export", params={"format": "json"})
    assert export.status_code == 200 and export.json()["summary"]["reliable"] is False


def test_openapi_declares_the_summarys_verdict(eval_client: Any) -> None:
    schemas = eval_client.get("/openapi.json").json()["components"]["schemas"]
    summary = schemas["EvaluationStatus"]["properties"]["summary"]
    assert {"$ref": "#/components/schemas/EvaluationSummary"} in summary["anyOf"]
    props = schemas["EvaluationSummary"]["properties"]
    assert props["warnings"]["type"] == "array"
    assert props["warnings"]["items"] == {"type": "string"}
    assert props["reliable"]["type"] == "boolean"
    assert schemas["EvaluationSummary"]["additionalProperties"] is True


@pytest.mark.slow  # >= 3 s: the CLI loads the model
def test_cli_evaluate_prints_each_warning_on_stderr(store: Path, cli_runner: CountingRunner,
                                                   capsys: pytest.CaptureFixture[str],
                                                   acc_cli_run: CliRun,
                                                   shared_model: None) -> None:
    """A tiny campaign whose stand-in never collides: the JSON as before on stdout (with
    warnings and reliable), one "warning: ..." line per warning on stderr after it, exit
    code 0 (also with -q)."""
    from app.cli import main

    cli_runner.dv_hit = 1e9
    assert main(["evaluate", "--sut", "acc", "--max-runs", "60", "--batch-size", "30",
                 "--seed", "1", "-q"]) == 0
    out = capsys.readouterr()
    summary = json.loads(out.out)
    assert summary["runs"] == 60 and summary["collisions"] == 0
    assert summary["reliable"] is False
    lines = out.err.strip().splitlines()
    assert lines == [f"warning: {w}" for w in summary["warnings"]]
    assert lines[0].startswith("warning: no collision in 60 draws: P(collision) is not "
                               "estimated")
    assert lines[1].startswith("warning: stopped at max_runs (60 draws)")
    # a reliable campaign prints no warning line: the shared one (1,500 draws, the stand-in
    # collides often)
    summary = json.loads(acc_cli_run.out)
    assert summary["collisions"] >= 10 and summary["ess"] >= 10
    assert summary["warnings"] == [] and summary["reliable"] is True
    assert "warning:" not in acc_cli_run.err
