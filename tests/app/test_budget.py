"""The time budget of synchronous requests (issue 27 item 3, finding 2): a read or a
POST /scenarios whose sampling runs past SCENGEN_SYNC_BUDGET_SECONDS is stopped and
answered 422 saying how to get it as a job (before: 200 or 422 after 25-102 s); a job's
request is not refused for a rare region (the job estimates it); a client that has gone
stops its work and nothing is stored."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app import budget
from app.errors import InvalidInput
from tests.app.factories import TEST_MODEL_OPTIONS, copy_model_cache, make_app, make_settings

RARE = "btn>0.9"  # 17 s to estimate on the default model (benchmarks/bench_regions.py)


@pytest.fixture(scope="module")
def budget_client(model_cache_dir: Path,
                  tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    data_dir = tmp_path_factory.mktemp("budget")
    copy_model_cache(model_cache_dir, data_dir)
    with TestClient(make_app(make_settings(data_dir, sync_budget_seconds=0.5))) as client:
        yield client


def _refused(r: Any) -> None:
    assert r.status_code == 422, r.text[:300]
    message = r.json()["error"]["message"]
    assert "SCENGEN_SYNC_BUDGET_SECONDS" in message and "POST /catalogues" in message


@pytest.mark.parametrize("path", [
    f"/dashboard/api/models/default/shift?constraints={RARE}",
    f"/dashboard/api/models/default/rates?constraints={RARE}",
    pytest.param(f"/models/compare?a=default&b=default&constraints={RARE}",
                 marks=pytest.mark.slow),
])
def test_an_expensive_read_over_the_budget_is_refused_saying_how_to_get_it(
        budget_client: Any, path: str) -> None:
    _refused(budget_client.get(path))


def test_post_scenarios_over_the_budget_is_refused(budget_client: Any) -> None:
    _refused(budget_client.post("/scenarios", json={"n": 5, "constraints": ["btn>0.95"]}))


@pytest.mark.slow
def test_a_cheap_request_is_answered(budget_client: Any) -> None:
    r = budget_client.post("/scenarios", json={"n": 2, "constraints": ["ttc<3"],
                                               "score": False})
    assert r.status_code == 200, r.text[:300]


def test_a_job_for_a_rare_region_is_accepted_its_check_left_to_the_job(
        budget_client: Any) -> None:
    r = budget_client.post("/catalogues", json={"n": 2, "constraints": [RARE],
                                                "score": False})
    assert r.status_code == 202, r.text[:300]
    assert budget_client.delete(f"/catalogues/{r.json()['id']}").status_code == 204


def test_the_budget_check_refuses_past_the_deadline_and_for_a_gone_client() -> None:
    b = budget.Budget(0.0, started=0.0)
    with pytest.raises(budget.OverBudget) as over:
        b.check()
    assert isinstance(over.value, InvalidInput)
    budget.Budget(60.0).check()  # within
    gone = budget.Budget(60.0, gone=lambda: True)
    with pytest.raises(budget.ClientGone):
        gone.check()
    with pytest.raises(budget.ClientGone):
        gone.check_client()
    budget.check()  # outside a request: nothing to check


def test_a_fit_whose_client_has_gone_stores_no_model(model_cache_dir: Path,
                                                     tmp_path: Path) -> None:
    """Before: POST /models kept fitting after its client gave up and stored a model no
    one received."""
    from app.services import models as models_service
    from app.services.store import open_context

    copy_model_cache(model_cache_dir, tmp_path)
    ctx = open_context(make_settings(tmp_path))
    try:
        before = [m.id for m in models_service.list_models(ctx)]
        token = budget.BUDGET.set(budget.Budget(600.0, gone=lambda: True))
        try:
            with pytest.raises(budget.ClientGone):
                models_service.fit_on_dataset(ctx, str(ctx.default_dataset_id),
                                              TEST_MODEL_OPTIONS)
        finally:
            budget.BUDGET.reset(token)
        assert [m.id for m in models_service.list_models(ctx)] == before
    finally:
        ctx.close()


@pytest.mark.slow
def test_a_client_that_disconnects_stops_its_sampling(model_cache_dir: Path,
                                                      tmp_path: Path) -> None:
    """Over real HTTP (uvicorn): a client that gives up on a slow read after 1 s; the
    service notices at the sampler's next progress report and stops (its log says so;
    before: the estimate ran to its end for nobody)."""
    import httpx

    from tests.app.factories import service_env, uvicorn_service, wait_for

    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    env = service_env(data_dir, sync_budget_seconds="600", local_workers="0",
                      warm_start="false")
    log = tmp_path / "uvicorn.log"
    with uvicorn_service(env, log, "--log-level", "info") as base:
        with pytest.raises(httpx.TimeoutException):
            httpx.get(f"{base}/dashboard/api/models/default/rates",
                      params={"constraints": "btn>0.95"}, timeout=1.0)
        wait_for(lambda: "the client has gone; its work was stopped" in log.read_text(),
                 "the service to stop the work", attempts=600)
