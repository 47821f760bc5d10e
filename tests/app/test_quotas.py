"""Per-client quotas (issue 27 item 1): one client cannot queue more than
SCENGEN_CLIENT_JOBS_LIMIT jobs nor SCENGEN_CLIENT_QUEUED_SCENARIOS_LIMIT scenarios; the
429 names the setting and carries Retry-After; another client is not affected; a job's
share is given back when it ends."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.errors import TooManyRequests
from app.quotas import ClientQuotas
from app.settings import Settings
from tests.app.factories import copy_model_cache, make_app, make_settings, wait_for

LIMITS = {"client_jobs_limit": 2, "client_queued_scenarios_limit": 10, "quota_retry_after": 7}


def test_quotas_count_jobs_and_scenarios_per_client() -> None:
    settings = Settings(**LIMITS)
    q = ClientQuotas()
    a = q.admit("alice", 6, settings)
    with pytest.raises(TooManyRequests) as over:
        q.admit("alice", 5, settings)  # 6 + 5 > 10
    assert "SCENGEN_CLIENT_QUEUED_SCENARIOS_LIMIT" in over.value.message
    assert over.value.headers == {"Retry-After": "7"} and over.value.status == 429
    q.admit("alice", 4, settings)  # 10: at the limit is allowed
    with pytest.raises(TooManyRequests) as jobs:
        q.admit("alice", 0, settings)  # a third job
    assert "SCENGEN_CLIENT_JOBS_LIMIT" in jobs.value.message
    assert q.usage("bob") == (0, 0)
    q.admit("bob", 10, settings)  # bob has his own quota
    q.release(a)
    assert q.usage("alice") == (1, 4)
    q.admit("alice", 6, settings)
    with pytest.raises(RuntimeError), q.hold("carol", 3, settings):
        raise RuntimeError("the job could not be stored")
    assert q.usage("carol") == (0, 0)  # released: nothing was queued


@pytest.fixture(scope="module")
def quota_app(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    data_dir = tmp_path_factory.mktemp("quotas")
    copy_model_cache(model_cache_dir, data_dir)
    yield make_app(make_settings(data_dir, **LIMITS))


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_a_flooding_client_gets_429_and_others_still_get_in(quota_app: Any) -> None:
    from fastapi.testclient import TestClient

    gate = threading.Event()
    with TestClient(quota_app, client=("10.0.0.1", 5000)) as flood, \
            TestClient(quota_app, client=("10.0.0.2", 5000)) as other:
        runner = quota_app.state.jobs.runner
        real = runner.region

        def held(spec: Any, stage: Any) -> Any:  # the job thread waits: jobs stay queued
            gate.wait(120)
            return real(spec, stage)

        runner.region = held
        try:
            body = {"n": 4, "seed": 1, "constraints": ["ttc<3"], "score": False}
            ids = [flood.post("/catalogues", json=body) for _ in range(2)]
            assert [r.status_code for r in ids] == [202, 202]
            r = flood.post("/catalogues", json={**body, "n": 1})
            assert r.status_code == 429, r.text
            assert r.headers["retry-after"] == "7"
            assert "SCENGEN_CLIENT_JOBS_LIMIT" in r.json()["error"]["message"]
            r = other.post("/catalogues", json={**body, "n": 11})
            assert r.status_code == 429 and r.json()["error"]["field"] == "body.n"
            assert "SCENGEN_CLIENT_QUEUED_SCENARIOS_LIMIT" in r.json()["error"]["message"]
            r = other.post("/catalogues", json=body)
            assert r.status_code == 202, r.text  # the flood does not touch the other client
        finally:
            gate.set()
            runner.region = real
        for r in ids:
            cid = r.json()["id"]
            wait_for(lambda cid=cid: flood.get(f"/catalogues/{cid}").json()["status"] == "done",
                     f"catalogue {cid}")
        # the finished jobs gave their share back
        wait_for(lambda: quota_app.state.jobs.quotas.usage("10.0.0.1") == (0, 0), "release")
        assert flood.post("/catalogues", json=body).status_code == 202


def test_a_bad_catalogue_request_is_422_even_over_the_quota(quota_app: Any) -> None:
    """A client whose job slots are full sends a bad constraint: it is told what is wrong
    (422 naming the constraint), not to wait (429), as POST /evaluations does; a valid
    request still gets the 429."""
    from fastapi.testclient import TestClient

    with TestClient(quota_app, client=("10.0.0.3", 5000)) as c:
        quotas = quota_app.state.jobs.quotas
        settings = quota_app.state.ctx.settings
        tokens = [quotas.admit("10.0.0.3", 1, settings) for _ in range(2)]
        try:
            r = c.post("/catalogues", json={"n": 4, "seed": 1, "constraints": ["foo<3"]})
            assert r.status_code == 422, r.text
            assert r.json()["error"]["field"].startswith("body.constraints"), r.json()
            r = c.post("/catalogues", json={"n": 4, "seed": 1, "constraints": ["ttc<3"],
                                            "sampler": "subset", "score": False})
            assert r.status_code == 429, r.text
            r = c.post("/catalogues", json={"n": 4, "seed": 1, "constraints": [],
                                            "sampler": "subset"})
            assert r.status_code == 422 and r.json()["error"]["field"] == "body.constraints"
        finally:
            for t in tokens:
                quotas.release(t)
