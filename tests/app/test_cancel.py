"""Cancellation (issue 27 item 2, finding 6): DELETE on a running catalogue or evaluation
stops the work in flight, not only what is still queued; a job cancelled during its P(A)
estimate stops there; the CLI's Ctrl-C leaves the catalogue ``cancelled`` and says how to
resume it."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.db import repository as repo
from app.jobs import CatalogueRunner, CatalogueSpec, InlineExecutor
from tests.app.factories import (
    copy_model_cache,
    make_app,
    make_settings,
    share_models,
    wait_for,
)
from tests.app.test_jobs import _catalogue, _db, fake_chunk

CHUNK = 400  # scenarios of the one chunk the catalogue tests run


class ScoringSpy:
    """Wraps ``app.jobs.chunk.score_rows`` (the real one runs): counts the scenarios
    scored and sets ``started`` once a few are, so the test acts while the chunk runs."""

    def __init__(self, real: Any) -> None:
        self.real = real
        self.scored = 0
        self.started = threading.Event()

    def __call__(self, *args: Any, **kwargs: Any) -> Iterator[Any]:
        for item in self.real(*args, **kwargs):
            self.scored += 1
            if self.scored >= 3:
                self.started.set()
            time.sleep(0.002)  # a chunk long enough to be caught running
            yield item


@pytest.fixture
def cancel_app(model_cache_dir: Path, tmp_path: Path,
               monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, ScoringSpy]]:
    """A service whose chunks run inline in the job thread (local_workers 0)."""
    from fastapi.testclient import TestClient

    import app.jobs.chunk as chunk

    spy = ScoringSpy(chunk.score_rows)
    monkeypatch.setattr(chunk, "score_rows", spy)
    copy_model_cache(model_cache_dir, tmp_path)
    with TestClient(make_app(make_settings(tmp_path, chunk_size=CHUNK))) as client:
        yield client, spy


def _start(client: Any, spy: ScoringSpy) -> str:
    r = client.post("/catalogues", json={"n": CHUNK, "seed": 5, "constraints": ["ttc<3"]})
    assert r.status_code == 202, r.text
    assert spy.started.wait(120), "the chunk never started"
    return str(r.json()["id"])


@pytest.mark.slow
def test_delete_stops_the_chunk_in_flight(cancel_app: tuple[Any, ScoringSpy]) -> None:
    client, spy = cancel_app
    cid = _start(client, spy)
    assert client.delete(f"/catalogues/{cid}").status_code == 204
    jobs = client.app.state.jobs
    wait_for(jobs.idle, "the job to end")
    # before: the chunk ran to its end (400 scored) and only its storing failed
    assert spy.scored < CHUNK
    assert not (client.app.state.ctx.data_dir / "catalogues" / cid).exists()


@pytest.mark.slow
def test_a_cancelled_catalogue_stops_its_chunk_and_says_cancelled(
        cancel_app: tuple[Any, ScoringSpy]) -> None:
    client, spy = cancel_app
    cid = _start(client, spy)
    jobs = client.app.state.jobs
    jobs.cancel(cid)
    wait_for(jobs.idle, "the job to end")
    assert spy.scored < CHUNK
    body = client.get(f"/catalogues/{cid}").json()
    assert body["status"] == "cancelled" and body["scenarios_stored"] == 0


def test_a_cancel_during_the_p_a_estimate_stops_it(tmp_path: Path) -> None:
    """The estimate hears its stages; once the job is cancelled the next stage ends it
    (before: the estimate ran on to its end, 50 stages here, then the job said cancelled)."""
    db = _db(tmp_path)
    _catalogue(db, "p")
    cancel = threading.Event()
    stages: list[int] = []

    def slow_region(spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
        for k in range(50):
            stages.append(k)
            if k == 2:
                cancel.set()
            stage("pilot", k, 50)
        return {"estimate": 0.25, "ci": [0.2, 0.3]}

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(fake_chunk), region=slow_region)
    assert runner.run("p", cancel=cancel) == "cancelled"
    assert stages == [0, 1, 2]
    with db.session() as s:
        assert repo.get_catalogue(s, "p").status == "cancelled"
        assert repo.get_catalogue(s, "p").p_region is None  # estimated again on resume
    assert runner.run("p") == "done"  # and it resumes


@pytest.mark.slow
def test_a_cancelled_evaluation_stops_between_the_parts_of_a_chunk(
        model_cache_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        shared_models: dict[str, Any]) -> None:
    """One chunk of 5000 draws, about half of them inside the region and simulated, in
    parts of 1024; the job is cancelled while the first part runs: no other part is
    simulated (before: all were, and the job stopped only once the chunk was done)."""
    from app.services import evaluations as service
    from app.services.store import open_context
    from tests.app.test_evaluations import CountingRunner

    copy_model_cache(model_cache_dir, tmp_path)
    share_models(monkeypatch, shared_models)  # its memo is not what is tested
    ctx = open_context(make_settings(tmp_path))
    try:
        cancel = threading.Event()

        class Cancelling(CountingRunner):
            def __call__(self, params: Any, seeds: Any) -> Any:
                cancel.set()
                return super().__call__(params, seeds)

        runner = Cancelling()
        ctx.campaign_runner = lambda factory, settings: runner
        eid = service.create(ctx, sut="acc", n=5000, batch_size=5000, seed=3).id
        assert service.run_job(ctx, eid, cancel=cancel) == "cancelled"
        assert 0 < runner.rows <= 1024  # the first part only (before: the whole chunk)
        assert service.describe(ctx, eid).status == "cancelled"
    finally:
        ctx.close()


@pytest.mark.slow
def test_ctrl_c_in_catalogue_create_leaves_cancelled_and_says_how_to_resume(
        store: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import json

    import app.jobs.chunk as chunk
    from app.cli import main

    real = chunk.compute_chunk

    def interrupted(spec: CatalogueSpec, index: int) -> Any:
        if index == 1:
            raise KeyboardInterrupt  # what Ctrl-C raises in the CLI's thread
        return real(spec, index)

    monkeypatch.setattr("app.jobs.executors.compute_chunk", interrupted)
    monkeypatch.setattr(InlineExecutor.__init__, "__defaults__", (interrupted,))
    assert main(["catalogue", "create", "--n", "4", "--seed", "3", "--chunk-size", "2",
                 "--constraint", "ttc<3", "--no-score"]) == 130
    err = capsys.readouterr().err
    cid = err.split("catalogue ", 1)[1].split(":", 1)[0]
    assert f"scengen catalogue resume {cid}" in err and "cancelled" in err
    assert "2 of 4 scenarios stored" in err
    assert main(["catalogue", "status", cid]) == 0
    status = json.loads(capsys.readouterr().out)
    assert status["status"] == "cancelled"  # before: "running", with nothing running
    monkeypatch.undo()
    assert main(["catalogue", "resume", cid]) == 0
