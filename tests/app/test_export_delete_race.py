"""The export/delete race and deleted-job leftovers (issue 27 item 5): an export either
completes from a consistent snapshot or answers 404, never 500 nor a truncated file; a
catalogue deleted while queued or running leaves no folder behind.

The race is made deterministic: the export's item stream is wrapped so that the DELETE
runs (through the real service) between two items, i.e. after the export has read the rows
and opened the first chunk file, before it opens the next."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.services import catalogues as service
from tests.app.factories import wait_for

FORMATS = ("jsonl", "csv", "parquet", "xosc", "commonroad")


def _ctx(client: Any) -> Any:
    return client.app.state.ctx


def _done_catalogue(client: Any, seed: int) -> str:
    r = client.post("/catalogues", json={"n": 4, "seed": seed, "constraints": ["ttc<3"],
                                         "chunk_size": 2, "score": False})
    assert r.status_code == 202, r.text
    cid = r.json()["id"]
    wait_for(lambda: client.get(f"/catalogues/{cid}").json()["status"] == "done",
             f"catalogue {cid}")
    return cid


@pytest.mark.parametrize("fmt", FORMATS)
def test_delete_during_an_export_gives_404_not_500(client: Any, fmt: str,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    ctx = _ctx(client)
    cid = _done_catalogue(client, seed=40)
    real = service.iter_items
    deleted: list[str] = []

    def racing(ctx_: Any, catalogue_id: str) -> Iterator[Any]:
        for k, item in enumerate(real(ctx_, catalogue_id)):
            yield item
            if k == 0:  # the DELETE lands while the export is between two items
                assert client.delete(f"/catalogues/{catalogue_id}").status_code == 204
                deleted.append(catalogue_id)

    monkeypatch.setattr(service, "iter_items", racing)
    r = client.get(f"/catalogues/{cid}/export", params={"format": fmt})
    assert deleted == [cid]
    assert r.status_code == 404, (fmt, r.status_code, r.text[:300])
    body = r.json()["error"]
    assert body["field"] == "path.catalogue_id" and "deleted while" in body["message"]
    assert not (ctx.data_dir / "catalogues" / cid).exists()
    assert list((ctx.data_dir / "tmp").glob("export-*")) == []  # no half-written file kept


def test_an_export_not_raced_is_whole(client: Any) -> None:
    cid = _done_catalogue(client, seed=41)
    r = client.get(f"/catalogues/{cid}/export", params={"format": "csv"})
    assert r.status_code == 200 and len(r.text.strip().splitlines()) == 1 + 4
    assert client.delete(f"/catalogues/{cid}").status_code == 204
    r = client.get(f"/catalogues/{cid}/export", params={"format": "csv"})
    assert r.status_code == 404 and r.json()["error"]["field"] == "path.catalogue_id"


def test_rows_vanishing_under_an_export_are_not_a_short_file(
        client: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Before: with the rows deleted between two batches the export ended early and
    answered 200 with fewer scenarios than the catalogue has."""
    ctx = _ctx(client)
    cid = _done_catalogue(client, seed=42)
    real_batch = service.repo.scenario_batch
    calls: list[int] = []

    def batch(session: Any, catalogue_id: str, last: int, size: int) -> Any:
        calls.append(last)
        return real_batch(session, catalogue_id, last, 2)  # two rows a batch ...

    def racing(ctx_: Any, catalogue_id: str) -> Iterator[Any]:
        for k, item in enumerate(real(ctx_, catalogue_id)):
            yield item
            if k == 1:  # ... and the deletion after the first batch
                service.delete(ctx_, catalogue_id)

    real = service.iter_items
    monkeypatch.setattr(service.repo, "scenario_batch", batch)
    monkeypatch.setattr(service, "iter_items", racing)
    r = client.get(f"/catalogues/{cid}/export", params={"format": "parquet"})
    assert r.status_code == 404, r.text[:300]
    assert len(calls) >= 2
    assert not (ctx.data_dir / "catalogues" / cid).exists()


def test_a_catalogue_deleted_as_its_job_starts_leaves_no_folder_and_no_traceback(
        client: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """Before: the job, started just before the DELETE, wrote its stage file into a fresh
    folder and logged 'catalogue ... failed' with a traceback."""
    ctx = _ctx(client)
    started, release = threading.Event(), threading.Event()

    def slow_region(spec: Any, stage: Any) -> Any:
        started.set()
        release.wait(60)
        from app.jobs.runner import estimate_region
        return estimate_region(spec, stage)

    runner = client.app.state.jobs.runner
    monkeypatch.setattr(runner, "region", slow_region)
    r = client.post("/catalogues", json={"n": 2, "seed": 43, "constraints": ["ttc<3"],
                                         "score": False})
    cid = r.json()["id"]
    assert started.wait(60)  # the job is estimating P(A)
    with caplog.at_level("INFO", logger="scengen.jobs"):
        assert client.delete(f"/catalogues/{cid}").status_code == 204
        release.set()
        folder: Path = ctx.data_dir / "catalogues" / cid
        wait_for(lambda: "deleted while its job ran" in caplog.text,
                 f"the job of {cid} to end")
        # the job removes what it wrote after the deletion (bounded wait: fails if never)
        wait_for(lambda: not folder.exists(), f"the folder of {cid} to go")
    assert "Traceback" not in caplog.text and "failed" not in caplog.text
    assert client.get(f"/catalogues/{cid}").status_code == 404
