"""The job runner's bookkeeping with an injected chunk function (no domain code): chunks
stored as they finish, a failed job keeps them, a resumed job equals an uninterrupted one,
cancellation, and the seed derivation."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow, DatasetRow, ModelRow
from app.jobs import CatalogueRunner, CatalogueSpec, ChunkResult, InlineExecutor
from app.jobs.chunk import chunk_seed


def fake_chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
    """Deterministic stand-in for compute_chunk: rows from (seed, index) only."""
    start, stop = spec.bounds(index)
    rng = np.random.default_rng(chunk_seed(spec.seed, index))
    rows = [{"idx": i, "chunk_index": index,
             "params": {"gap": float(rng.uniform(5, 50)), "dv": 3.0},
             "ttc": 1.0, "risk": float(rng.uniform()), "exposure_weight": 1.0,
             "summary": {}} for i in range(start, stop)]
    return ChunkResult(index=index, rows=rows, blob=f"chunk {index}".encode())


class Exploding:
    """Fails at chunk ``at`` (a crash in the middle of a job)."""

    def __init__(self, at: int) -> None:
        self.at = at

    def __call__(self, spec: CatalogueSpec, index: int) -> ChunkResult:
        if index == self.at:
            raise RuntimeError(f"boom at chunk {index}")
        return fake_chunk(spec, index)


def region(spec: CatalogueSpec, stage: Any = None) -> dict[str, Any]:
    return {"estimate": 0.25, "ci": [0.2, 0.3]}


def _db(tmp_path: Path) -> Database:
    db = Database(f"sqlite:///{tmp_path / 'jobs.db'}")
    db.migrate()
    with db.session() as s:
        s.add(DatasetRow(id="ds", name="d", kind="embedded", embedded=True, data_hash="h",
                         n_cutins=1, table_path="x", report={}))
        s.flush()
        s.add(ModelRow(id="m", dataset_id="ds", is_default=True, options={}, n_components=1,
                       model_hash="mh", model_json="{}", bic_curve=[], fit_report={}))
    return db


def _catalogue(db: Database, cid: str, n: int = 23, seed: int = 11) -> None:
    with db.session() as s:
        s.add(CatalogueRow(id=cid, model_id="m", status="queued", n=n, seed=seed,
                           chunk_size=5, n_chunks=(n + 4) // 5,
                           spec={"constraints": ["ttc<3"], "method": "auto", "score": True}))


def _rows(db: Database, cid: str) -> list[tuple[Any, ...]]:
    with db.session() as s:
        return [(r.idx, r.chunk_index, r.params, r.risk)
                for r in repo.iter_scenarios(s, cid)]


def test_a_job_stores_every_chunk_and_p_region(tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "a")
    seen: list[tuple[int, int]] = []
    runner = CatalogueRunner(db, tmp_path, InlineExecutor(fake_chunk), region=region)
    assert runner.run("a", progress=lambda d, t: seen.append((d, t))) == "done"
    assert seen[0] == (0, 23) and seen[-1] == (23, 23)  # scenarios, not chunks
    with db.session() as s:
        row = repo.get_catalogue(s, "a")
        assert row.status == "done" and row.finished_at is not None
        assert row.p_region == {"estimate": 0.25, "ci": [0.2, 0.3]}
        assert repo.count_scenarios(s, "a") == 23
        files = [c.file_path for c in repo.chunk_rows(s, "a")]
    assert (tmp_path / str(files[4])).read_bytes() == b"chunk 4"
    assert [r[0] for r in _rows(db, "a")] == list(range(23))
    # running a finished job again changes nothing
    assert runner.run("a") == "done"
    assert len(_rows(db, "a")) == 23


def test_failed_job_keeps_its_chunks_and_resumes_to_the_same_result(tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "crashy")
    _catalogue(db, "clean")
    crashing = CatalogueRunner(db, tmp_path, InlineExecutor(Exploding(at=3)), region=region)
    assert crashing.run("crashy") == "failed"
    with db.session() as s:
        row = repo.get_catalogue(s, "crashy")
        assert row.status == "failed" and "boom at chunk 3" in (row.error or "")
        assert repo.stored_chunk_indices(s, "crashy") == {0, 1, 2}
    calls: list[int] = []

    def counting(spec: CatalogueSpec, index: int) -> ChunkResult:
        calls.append(index)
        return fake_chunk(spec, index)

    good = CatalogueRunner(db, tmp_path, InlineExecutor(counting), region=region)
    assert good.run("crashy") == "done"
    assert calls == [3, 4]  # only the missing chunks were computed
    CatalogueRunner(db, tmp_path, InlineExecutor(fake_chunk), region=region).run("clean")
    assert _rows(db, "crashy") == _rows(db, "clean")


def test_cancel_stops_between_chunks(tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "c")
    cancel = threading.Event()

    def cancelling(spec: CatalogueSpec, index: int) -> ChunkResult:
        if index == 1:
            cancel.set()
        return fake_chunk(spec, index)

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(cancelling), region=region)
    assert runner.run("c", cancel=cancel) == "cancelled"
    with db.session() as s:
        assert repo.get_catalogue(s, "c").status == "cancelled"
        assert repo.stored_chunk_indices(s, "c") == {0, 1}


def test_shutdown_leaves_the_job_resumable(tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "s")
    stop = threading.Event()

    def stopping(spec: CatalogueSpec, index: int) -> ChunkResult:
        stop.set()
        return fake_chunk(spec, index)

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(stopping), region=region)
    assert runner.run("s", stop=stop) == "interrupted"
    with db.session() as s:
        assert repo.get_catalogue(s, "s").status == "running"  # resumed at the next start


def test_seeds_depend_only_on_catalogue_seed_and_index() -> None:
    assert chunk_seed(5, 3) == chunk_seed(5, 3)
    assert len({chunk_seed(5, i) for i in range(1000)}) == 1000
    assert chunk_seed(5, 3) != chunk_seed(6, 3)
    assert all(0 <= chunk_seed(9, i) < 2**31 for i in range(100))


def test_spec_bounds_cover_n_exactly() -> None:
    spec = CatalogueSpec(n=23, seed=1, chunk_size=5, model_json="{}", constraints=("ttc<3",))
    assert spec.n_chunks == 5
    assert [spec.bounds(i) for i in range(5)] == [(0, 5), (5, 10), (10, 15), (15, 20),
                                                  (20, 23)]
    with pytest.raises(IndexError):
        spec.bounds(5)
    assert CatalogueSpec.from_dict(spec.to_dict()) == spec


def test_progress_moves_per_scenario_while_a_chunk_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # issue 14 item 6: workers report each scenario (app.db.chunkfile progress files); the
    # runner's meter passes the count on before the chunk is stored
    from app.db import chunkfile
    from app.jobs import runner as runner_module
    from tests.app.factories import wait_for

    monkeypatch.setattr(runner_module, "PROGRESS_TICK", 0.01)
    seen: list[tuple[int, int]] = []

    def reporting_chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
        assert spec.progress_dir is not None
        start, stop = spec.bounds(index)
        for k in range(1, stop - start):
            chunkfile.write_progress(spec.progress_dir, index, k)
            wait_for(lambda k=k: bool(seen) and seen[-1][0] == start + k,  # type: ignore[misc]
                     f"scenario {start + k} reported", attempts=500, pause=0.01)
        return fake_chunk(spec, index)

    db = _db(tmp_path)
    _catalogue(db, "p", n=12)  # chunks of 5, 5, 2
    runner = CatalogueRunner(db, tmp_path, InlineExecutor(reporting_chunk), region=region)
    assert runner.run("p", progress=lambda d, t: seen.append((d, t))) == "done"
    assert [d for d, _ in seen] == list(range(13))  # 0, 1, ..., 12: every scenario
    assert {t for _, t in seen} == {12}
    assert chunkfile.read_progress(chunkfile.progress_dir(tmp_path, "p")) == {}  # cleared


def test_scenarios_done_counts_stored_chunks_and_reports(tmp_path: Path) -> None:
    from app.db import chunkfile
    from app.jobs.runner import scenarios_done

    # n = 12 in chunks of 5: sizes 5, 5, 2
    assert scenarios_done(12, 5, set(), tmp_path) == 0
    assert scenarios_done(12, 5, {0, 2}, tmp_path) == 7
    chunkfile.write_progress(tmp_path, 1, 3)
    chunkfile.write_progress(tmp_path, 2, 2)  # stored already: counted once
    chunkfile.write_progress(tmp_path, 7, 4)  # no such chunk: ignored
    assert scenarios_done(12, 5, {0, 2}, tmp_path) == 10
    chunkfile.write_progress(tmp_path, 1, 9)  # more than the chunk holds: capped
    assert scenarios_done(12, 5, {0, 2}, tmp_path) == 12


def test_an_unresolved_model_interval_is_refined_once_the_scenarios_are_stored(
        tmp_path: Path) -> None:
    from app.jobs.runner import refine_region

    db = _db(tmp_path)
    _catalogue(db, "r")
    unresolved = {"estimate": 0.25, "ci": [0.2, 0.3],
                  "model_interval": {"ci": [0.01, 0.9], "lower_resolved": False,
                                     "upper_resolved": True}}
    calls: list[tuple[int, dict[str, Any]]] = []

    def refine(spec: CatalogueSpec, p_region: dict[str, Any]) -> dict[str, Any] | None:
        with db.session() as s:
            calls.append((repo.count_scenarios(s, "r"), p_region))
        return {**p_region, "model_interval": {"ci": [0.0, 0.8], "lower_resolved": True,
                                                "upper_resolved": True}}

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(fake_chunk),
                             region=lambda spec, stage: unresolved, refine=refine)
    notes: list[str] = []
    assert runner.run("r", note=notes.append) == "done"
    assert calls == [(23, unresolved)]  # once, after all 23 scenarios were stored
    assert len(notes) == 1 and "refining the model interval" in notes[0]
    with db.session() as s:
        assert repo.get_catalogue(s, "r").p_region["model_interval"]["ci"] == [0.0, 0.8]
    # nothing to refine: no model interval, or both ends resolved (no domain code runs)
    spec = CatalogueSpec(n=1, seed=0, chunk_size=1, model_json="{}", constraints=("ttc<3",))
    assert refine_region(spec, {"estimate": 0.1, "ci": [0.0, 0.2]}) is None
    assert refine_region(spec, {"estimate": 0.1, "model_interval": {
        "lower_resolved": True, "upper_resolved": True}}) is None


def test_the_stage_file_says_what_the_job_is_doing_and_goes_at_the_end(
        tmp_path: Path) -> None:
    from app.db import chunkfile

    db = _db(tmp_path)
    _catalogue(db, "s")
    folder = chunkfile.progress_dir(tmp_path, "s")
    seen: list[dict[str, Any] | None] = []

    def slow_region(spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
        seen.append(chunkfile.read_stage(folder))
        stage("pilot", 5, 10)
        seen.append(chunkfile.read_stage(folder))
        stage("pilot", 6, 10)  # the same stage again within STAGE_EVERY: not rewritten
        seen.append(chunkfile.read_stage(folder))
        stage("subset-is", 0, 1)  # a new stage: written at once
        seen.append(chunkfile.read_stage(folder))
        return region(spec)

    def chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
        seen.append(chunkfile.read_stage(folder))
        return fake_chunk(spec, index)

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(chunk), region=slow_region)
    assert runner.run("s") == "done"
    assert seen[:4] == [
        {"name": "estimating P(A): starting", "done": 0, "total": 1},
        {"name": "estimating P(A): pilot", "done": 5, "total": 10},
        {"name": "estimating P(A): pilot", "done": 5, "total": 10},
        {"name": "estimating P(A): subset-is", "done": 0, "total": 1}]
    assert seen[4:] == [{"name": "sampling and scoring", "done": None, "total": None}] * 5
    assert chunkfile.read_stage(folder) is None  # cleared when the job ends
    # and when it fails
    _catalogue(db, "f")
    failing = CatalogueRunner(db, tmp_path, InlineExecutor(Exploding(at=1)), region=slow_region)
    assert failing.run("f") == "failed"
    assert chunkfile.read_stage(chunkfile.progress_dir(tmp_path, "f")) is None
