"""The campaign's adaptation chosen from the CLI and the API (issue 24 item 7/9):
``scengen evaluate --adapt {ce,kernels}`` (ce the default) and ``POST /evaluations
{"adapt": ...}`` reach ``sampler.campaign.evaluate(adapt=...)``; a stored spec without
the field is a kernels campaign and resumes as one.

The runner is a stand-in whose outcome is known by hand (a collision iff dv > 6 m/s) and
which reports the ``margin`` the cross-entropy stage scores (6 - dv: <= 0 iff collided)."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app import jsonconv
from app.services import evaluations as service
from app.services.store import open_context
from datasets import PARAM_NAMES
from tests.app.factories import copy_model_cache, make_settings, share_models
from tests.app.test_evaluations import CountingRunner, Outcomes, _done

DV_HIT = 6.0


class ScoredOutcomes(Outcomes):
    def __init__(self, params: np.ndarray, dv_hit: float) -> None:
        super().__init__(params, dv_hit)
        dv = params[:, PARAM_NAMES.index("dv")]
        self.margin = dv_hit - dv  # the signed distance to the collision set


class ScoredRunner(CountingRunner):
    def __call__(self, params: np.ndarray, seeds: np.ndarray) -> Outcomes:
        self.rows += params.shape[0]
        return ScoredOutcomes(np.asarray(params), self.dv_hit)


@pytest.fixture
def cli_runner(monkeypatch: pytest.MonkeyPatch) -> ScoredRunner:
    runner = ScoredRunner(DV_HIT)
    monkeypatch.setattr(service, "default_runner", lambda factory, settings: runner)
    return runner


@pytest.fixture(scope="module")
def models(shared_models: dict[str, Any]) -> dict[str, Any]:
    """The model object the module's contexts share (``share_models``: its memo, about
    9 s, estimated once): the test process's."""
    return shared_models


@pytest.fixture(scope="module")
def client(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory,
           models: dict[str, Any]) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    from tests.app.factories import make_app

    data_dir = tmp_path_factory.mktemp("evaluations-adapt")
    copy_model_cache(model_cache_dir, data_dir)
    runner = ScoredRunner(DV_HIT)
    app = make_app(make_settings(data_dir))
    start = pytest.MonkeyPatch()
    share_models(start, models)  # for the app's start only
    try:
        with TestClient(app) as c:
            start.undo()
            app.state.ctx.campaign_runner = lambda factory, settings: runner
            yield c
    finally:
        start.undo()


# --------------------------------------------------------------------------- spec
def test_a_stored_spec_without_adapt_reads_as_kernels() -> None:
    old = {"sut": "acc", "sut_params": {}, "constraints": [], "n": 100, "rhw": 0.3,
           "max_runs": 200000, "seed": 1, "batch_size": 50, "settings": None,
           "risk": False}
    spec = service.CampaignSpec.from_dict(old)
    assert spec.adapt == "kernels"
    assert service.CampaignSpec.from_dict({**old, "adapt": "ce"}).adapt == "ce"
    assert spec.to_dict() == {**old, "adapt": "kernels", "band_step": False}


def test_a_stored_spec_without_band_step_reads_as_off() -> None:
    """Specs stored before ``band_step`` existed ran without it and resume without it."""
    old = {"sut": "acc", "sut_params": {}, "constraints": [], "n": 100, "rhw": 0.3,
           "max_runs": 200000, "seed": 1, "batch_size": 50, "settings": None,
           "risk": False, "adapt": "ce"}
    assert service.CampaignSpec.from_dict(old).band_step is False
    on = service.CampaignSpec.from_dict({**old, "band_step": True})
    assert on.band_step is True
    assert service.CampaignSpec.from_dict(on.to_dict()) == on


def test_band_step_is_off_by_default_everywhere(tmp_path: Path) -> None:
    """The sampler's default (off: measured worse at P near 1e-3, docs/evaluation.md) is
    the service's, the request's, the OpenAPI schema's and the CLI's."""
    import dataclasses
    import inspect

    from app.routes.evaluations import EvaluationRequest
    from sampler.campaign import evaluate
    from tests.app.test_stop_rule_default import _evaluate_parser, _openapi_request

    [flag] = [a for a in _evaluate_parser()._actions if a.dest == "band_step"]
    defaults = {
        "evaluate()": inspect.signature(evaluate).parameters["band_step"].default,
        "create()": inspect.signature(service.create).parameters["band_step"].default,
        "validate()": inspect.signature(service.validate).parameters["band_step"].default,
        "CampaignSpec": {f.name: f.default for f in
                         dataclasses.fields(service.CampaignSpec)}["band_step"],
        "EvaluationRequest": EvaluationRequest(sut="acc").band_step,
        "OpenAPI": _openapi_request(tmp_path)["properties"]["band_step"]["default"],
        "--band-step": flag.default,
    }
    assert {k: v for k, v in defaults.items() if v is not False} == {}


# --------------------------------------------------------------------------- CLI
@pytest.mark.slow  # two campaigns of 1,500 draws on a loaded machine
def test_cli_adapt_ce_runs_a_cross_entropy_campaign(
        store: Path, cli_runner: ScoredRunner, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, models: dict[str, Any]) -> None:
    from app.cli import main

    share_models(monkeypatch, models)  # the calls reuse the module's model object
    argv = ["evaluate", "--sut", "acc", "-n", "1500", "--seed", "4", "--batch-size", "500",
            "-q"]
    assert main(argv) == 0  # the default is ce
    ce = json.loads(capsys.readouterr().out)
    assert ce["adapt"] == "ce"
    # chunk 0 is always a pilot chunk (no elite yet); the stand-in collides often enough
    # (>= 20 collided runs in 500) that the final stage starts at chunk 1
    assert ce["pilot_runs"] == 500 and ce["runs"] == 1500
    assert any(str(p.get("part", "")).startswith("ce:") for p in ce["proposal"]), \
        ce["proposal"]
    assert main([*argv, "--adapt", "kernels"]) == 0
    kernels = json.loads(capsys.readouterr().out)
    assert kernels["adapt"] == "kernels" and kernels["pilot_runs"] == 0
    assert kernels["p_collision"] != ce["p_collision"]


@pytest.mark.parametrize("value", ["CE", "cem", ""])
def test_cli_bad_adapt_is_one_line_and_exit_2(store: Path, cli_runner: ScoredRunner,
                                              capsys: pytest.CaptureFixture[str],
                                              value: str) -> None:
    from app.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "-q", "--sut", "acc", "-n", "5", "--adapt", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "--adapt" in err and "kernels" in err and "ce" in err
    assert cli_runner.rows == 0


def test_cli_band_step_with_kernels_is_one_line_and_nonzero(
        store: Path, cli_runner: ScoredRunner, capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    code = main(["evaluate", "-q", "--sut", "acc", "-n", "5", "--adapt", "kernels",
                 "--band-step"])
    assert code != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.count("--band-step") == 1 and "'kernels'" in err
    assert cli_runner.rows == 0


def test_cli_help_names_the_choices(capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--adapt {ce,kernels}" in out and "default: adaptive cross-entropy" in out


# --------------------------------------------------------------------------- API
def test_post_adapt_ce_gives_the_direct_campaign_bit_for_bit(client: Any) -> None:
    from sampler.campaign import evaluate

    r = client.post("/evaluations", json={"sut": "acc", "n": 1500, "batch_size": 500,
                                          "seed": 5, "adapt": "ce"})
    assert r.status_code == 202, r.json()
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert st["spec"]["adapt"] == "ce"
    got = st["summary"]
    assert got["adapt"] == "ce" and got["pilot_runs"] == 500

    ctx = client.app.state.ctx
    model = ctx.model(ctx.resolve_model_id(None))
    direct = evaluate(model, ScoredRunner(DV_HIT), n=1500, batch_size=500, seed=5,
                      sut="acc", adapt="ce", roulette=service.DEFAULT_ROULETTE,
                      final_alpha=service.ROULETTE_FINAL_ALPHA,
                      max_runs=min(service.DEFAULT_MAX_RUNS,
                                   ctx.settings.catalogue_n_limit))
    want = json.loads(json.dumps(jsonconv.encode(direct.summary())))
    assert got == want  # every number, bit for bit (JSON floats round-trip exactly)


def test_post_default_is_ce_and_kernels_stays_available(client: Any) -> None:
    r = client.post("/evaluations", json={"sut": "acc", "n": 200, "batch_size": 100,
                                          "seed": 2})
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert st["spec"]["adapt"] == "ce"
    assert st["summary"]["adapt"] == "ce" and st["summary"]["runs"] == 200
    r = client.post("/evaluations", json={"sut": "acc", "n": 200, "batch_size": 100,
                                          "seed": 2, "adapt": "kernels"})
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert st["spec"]["adapt"] == "kernels"
    assert st["summary"]["adapt"] == "kernels" and st["summary"]["pilot_runs"] == 0


@pytest.mark.parametrize("value", ["cem", "CE", 1, None])
def test_post_bad_adapt_is_422_naming_the_field(client: Any, value: Any) -> None:
    before = len(client.get("/evaluations").json()["evaluations"])
    r = client.post("/evaluations", json={"sut": "acc", "n": 10, "adapt": value})
    assert r.status_code == 422, r.json()
    assert r.json()["error"]["field"] == "body.adapt", r.json()
    assert len(client.get("/evaluations").json()["evaluations"]) == before


def test_openapi_lists_the_adapt_values(client: Any) -> None:
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    prop = schema["EvaluationRequest"]["properties"]["adapt"]
    assert prop["enum"] == ["ce", "kernels"] and prop["default"] == "ce"


def test_service_refuses_an_unknown_adapt_naming_the_field(client: Any) -> None:
    from app.errors import InvalidInput

    with pytest.raises(InvalidInput) as exc:
        service.create(client.app.state.ctx, sut="acc", n=10, adapt="nope")
    assert exc.value.field == "body.adapt"


@pytest.mark.slow  # three campaigns of 1,500 draws on a loaded machine
def test_post_band_step_gives_the_direct_campaign_bit_for_bit(client: Any) -> None:
    """``{"band_step": true}`` reaches ``evaluate(band_step=True)``: the stored spec and
    the summary say so, the summary is the direct campaign's bit for bit, and the
    campaign is not the one without it."""
    from sampler.campaign import evaluate

    r = client.post("/evaluations", json={"sut": "acc", "n": 1500, "batch_size": 500,
                                          "seed": 6, "band_step": True})
    assert r.status_code == 202, r.json()
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert st["spec"]["band_step"] is True and st["spec"]["adapt"] == "ce"
    got = st["summary"]
    assert got["band_step"] is True

    ctx = client.app.state.ctx
    model = ctx.model(ctx.resolve_model_id(None))
    kw: dict[str, Any] = {"n": 1500, "batch_size": 500, "seed": 6, "sut": "acc",
                          "max_runs": min(service.DEFAULT_MAX_RUNS,
                                          ctx.settings.catalogue_n_limit)}
    kw["roulette"] = service.DEFAULT_ROULETTE  # the request's default with adapt ce
    kw["final_alpha"] = service.ROULETTE_FINAL_ALPHA  # and the model's share with it
    direct = evaluate(model, ScoredRunner(DV_HIT), band_step=True, **kw)
    assert got == json.loads(json.dumps(jsonconv.encode(direct.summary())))
    off = evaluate(model, ScoredRunner(DV_HIT), **kw).summary()
    assert off["band_step"] is False
    # the final stage's shares differ (set and band parts 0.2 with the step, 0.1 without)
    assert off["proposal"] != got["proposal"]
    # and the slow cutter's band is the narrower one (BAND_STEP_ENVELOPES)
    parts = {p["part"] for p in got["proposal"]}
    assert "band:v_cut_min<1.5" in parts and "band:v_cut_min<3" not in parts, parts
    assert "band:v_cut_min<3" in {p["part"] for p in off["proposal"]}


def test_post_band_step_with_kernels_is_422_naming_the_field(client: Any) -> None:
    r = client.post("/evaluations", json={"sut": "acc", "n": 10, "adapt": "kernels",
                                          "band_step": True})
    assert r.status_code == 422, r.json()
    assert r.json()["error"]["field"] == "body.band_step", r.json()
    assert "adapt 'ce'" in r.json()["error"]["message"]


# --------------------------------------------------------------------------- roulette
def test_a_stored_spec_without_roulette_reads_as_off() -> None:
    """Specs stored before the weight roulette existed ran without it and resume so."""
    old = {"sut": "acc", "sut_params": {}, "constraints": [], "n": 100, "rhw": 0.3,
           "max_runs": 200000, "seed": 1, "batch_size": 50, "settings": None,
           "risk": False, "adapt": "ce", "band_step": False}
    spec = service.CampaignSpec.from_dict(old)
    assert spec.roulette == 0.0 and spec.to_dict() == old
    on = service.CampaignSpec.from_dict({**old, "roulette": 5.0})
    assert on.roulette == 5.0
    assert service.CampaignSpec.from_dict(on.to_dict()) == on


def test_roulette_defaults_to_five_with_ce_and_off_with_kernels(tmp_path: Path) -> None:
    """A new campaign of the service and the CLI runs the roulette (factor 5) with adapt
    'ce' unless told otherwise; the Python ``evaluate()`` runs without unless asked."""
    import inspect

    from app.routes.evaluations import EvaluationRequest
    from sampler.campaign import evaluate
    from tests.app.test_stop_rule_default import _evaluate_parser, _openapi_request

    assert service.DEFAULT_ROULETTE == 5.0
    assert service.default_roulette("ce", None) == 5.0
    assert service.default_roulette("kernels", None) == 0.0
    assert service.default_roulette("ce", 0) == 0.0
    assert service.default_roulette("ce", 12.5) == 12.5
    [flag] = [a for a in _evaluate_parser()._actions if a.dest == "roulette"]
    assert flag.default is None  # resolved by default_roulette with --adapt
    assert EvaluationRequest(sut="acc").roulette is None
    assert _openapi_request(tmp_path)["properties"]["roulette"].get("default") is None
    assert inspect.signature(evaluate).parameters["roulette"].default == 0.0


def test_post_default_runs_the_roulette_and_stores_it(client: Any) -> None:
    r = client.post("/evaluations", json={"sut": "acc", "n": 1500, "batch_size": 500,
                                          "seed": 3})
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert st["spec"]["roulette"] == 5.0
    got = st["summary"]
    assert got["roulette"] == 5.0 and got["skipped_runs"] > 0
    assert got["sut_runs"] + got["skipped_runs"] <= got["runs"]
    # with it the final stage's model share: stored, reported, and in the last proposal
    assert st["spec"]["final_alpha"] == 0.05
    assert got["alpha"] == 0.15 and got["final_alpha"] == 0.05
    assert _model_share(got["proposal"]) == pytest.approx(0.05, rel=1e-9)
    r = client.post("/evaluations", json={"sut": "acc", "n": 1500, "batch_size": 500,
                                          "seed": 3, "roulette": 0})
    st = _done(client, r.json()["id"])
    assert st["status"] == "done", st["error"]
    assert "roulette" not in st["spec"] and st["summary"]["skipped_runs"] == 0
    assert "final_alpha" not in st["spec"] and st["summary"]["final_alpha"] is None
    assert _model_share(st["summary"]["proposal"]) == pytest.approx(0.15, rel=1e-9)


def _model_share(proposal: list[dict[str, Any]]) -> float:
    [share] = [float(p["share"]) for p in proposal if p["part"] == "model"]
    return share


@pytest.mark.parametrize(("body", "message"), [
    ({"roulette": -1}, "greater than or equal"),
    ({"roulette": 1000}, "less than or equal"),
    ({"roulette": "lots"}, "number"),
    ({"adapt": "kernels", "roulette": 5}, "adapt 'ce'"),
])
def test_post_bad_roulette_is_422_naming_the_field(client: Any, body: dict[str, Any],
                                                   message: str) -> None:
    before = len(client.get("/evaluations").json()["evaluations"])
    r = client.post("/evaluations", json={"sut": "acc", "n": 10, **body})
    assert r.status_code == 422, r.json()
    err = r.json()["error"]
    assert err["field"] == "body.roulette", err
    assert message in err["message"], err
    assert len(client.get("/evaluations").json()["evaluations"]) == before


@pytest.mark.parametrize(("argv", "message"), [
    (["--roulette", "-2"], "[0, 100]"),
    (["--adapt", "kernels", "--roulette", "5"], "'kernels'"),
])
def test_cli_bad_roulette_is_one_line_and_nonzero(
        store: Path, cli_runner: ScoredRunner, capsys: pytest.CaptureFixture[str],
        argv: list[str], message: str) -> None:
    from app.cli import main

    code = main(["evaluate", "-q", "--sut", "acc", "-n", "5", *argv])
    assert code != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.count("--roulette") == 1 and message in err, err
    assert cli_runner.rows == 0


# --------------------------------------------------------------------------- resume
@pytest.mark.slow  # four campaigns of 1,500 draws on a loaded machine
def test_old_and_ce_specs_resume_to_the_uninterrupted_result(
        model_cache_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        models: dict[str, Any]) -> None:
    """An evaluation stored before the field existed (its spec has no "adapt") is
    interrupted and resumed: it runs as kernels, equal to a fresh kernels run; a ce
    evaluation interrupted and resumed equals an uninterrupted ce run."""
    from app.db.models import EvaluationRow

    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    share_models(monkeypatch, models)
    ctx = open_context(make_settings(data_dir))
    try:
        runner = ScoredRunner(DV_HIT)
        ctx.campaign_runner = lambda factory, settings: runner
        base: dict[str, Any] = {"sut": "acc", "n": 1500, "batch_size": 500, "seed": 7}
        for adapt in ("kernels", "ce"):
            a = service.create(ctx, **base, adapt=adapt).id
            b = service.create(ctx, **base, adapt=adapt).id
            if adapt == "kernels":  # as stored before the field existed
                with ctx.db.session() as s:
                    row = s.get(EvaluationRow, b)
                    assert row is not None
                    spec = dict(jsonconv.decode(row.spec))
                    del spec["adapt"]
                    row.spec = jsonconv.encode(spec)
            assert service.run_job(ctx, a) == "done"
            stop = threading.Event()

            def progress(stage: str, done: int, total: int, stop: Any = stop) -> None:
                if done >= 500:
                    stop.set()

            assert service.run_job(ctx, b, stop=stop, progress=progress) == "interrupted"
            assert service.describe(ctx, b).chunks_done == 1
            assert service.run_job(ctx, b) == "done"
            sa, sb = service.describe(ctx, a).summary, service.describe(ctx, b).summary
            assert sb["adapt"] == adapt
            assert sa == sb
            if adapt == "ce":
                assert sb["pilot_runs"] == 500
    finally:
        ctx.close()


# --------------------------------------------------------------------------- final alpha
def test_a_stored_spec_without_final_alpha_keeps_the_pilot_share() -> None:
    """Specs stored before the final stage had its own model share ran with the pilot's
    (None) and resume so; a spec with it round-trips."""
    old = {"sut": "acc", "sut_params": {}, "constraints": [], "n": 100, "rhw": 0.3,
           "max_runs": 200000, "seed": 1, "batch_size": 50, "settings": None,
           "risk": False, "adapt": "ce", "band_step": False, "roulette": 5.0}
    spec = service.CampaignSpec.from_dict(old)
    assert spec.final_alpha is None and spec.to_dict() == old
    new = service.CampaignSpec.from_dict({**old, "final_alpha": 0.05})
    assert new.final_alpha == 0.05 and new.to_dict()["final_alpha"] == 0.05
    assert service.CampaignSpec.from_dict(new.to_dict()) == new


def test_final_alpha_follows_the_roulette() -> None:
    """The CLI and the API run the model's final-stage share 0.05 with the roulette on and
    the pilot's share (None) with it off; ``evaluate()`` keeps ``alpha`` unless asked."""
    import inspect

    from sampler.campaign import evaluate

    assert service.ROULETTE_FINAL_ALPHA == 0.05
    assert service.default_final_alpha(5.0) == 0.05
    assert service.default_final_alpha(0.5) == 0.05
    assert service.default_final_alpha(0.0) is None
    assert inspect.signature(evaluate).parameters["final_alpha"].default is None
