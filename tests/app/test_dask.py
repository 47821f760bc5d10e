"""Same seed → identical catalogue export on the local process pool and on a real
two-worker dask.distributed LocalCluster (reached through SCENGEN_DASK_SCHEDULER)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.jobs import DaskExecutor, LocalPoolExecutor
from app.services import catalogues
from app.services.store import open_context
from tests.app.factories import copy_model_cache, make_settings


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", host="127.0.0.1") as local:
        yield local


def _build(data_dir: Path, tmp_path: Path, name: str, **settings: Any) -> tuple[Path, str]:
    ctx = open_context(make_settings(data_dir, chunk_size=3, **settings))
    try:
        row = catalogues.create(ctx, n=10, seed=2024, constraints=["ttc<3"], score=False)
        executor = ctx.executor
        assert ctx.runner().run(row.id) == "done"
        out = catalogues.export(ctx, row.id, "jsonl", tmp_path / f"{name}.jsonl")
        return out, executor.name
    finally:
        ctx.close()


@pytest.mark.slow
def test_local_pool_and_dask_give_the_same_catalogue(cluster: Any, tmp_path: Path,
                                                     model_cache_dir: Path) -> None:
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    local, local_kind = _build(data_dir, tmp_path, "local", local_workers=2)
    dask, dask_kind = _build(data_dir, tmp_path, "dask",
                             dask_scheduler=cluster.scheduler_address)
    assert (local_kind, dask_kind) == ("local", "dask")
    assert local.read_bytes() == dask.read_bytes()
    assert local.read_bytes().count(b'"kind":"scenario"') == 10


@pytest.mark.slow
def test_executors_are_what_the_settings_say(cluster: Any) -> None:
    from app.jobs import make_executor

    dask = make_executor(dask_scheduler=cluster.scheduler_address, local_workers=2)
    local = make_executor(dask_scheduler=None, local_workers=2)
    try:
        assert isinstance(dask, DaskExecutor) and isinstance(local, LocalPoolExecutor)
    finally:
        dask.close()
        local.close()


def _evaluate(data_dir: Path, model: Any = None, **settings: Any
              ) -> tuple[dict[str, Any], str, Any]:
    """The summary of one evaluation, the executor's name and the default model object.
    ``model``: that object from an earlier call, kept by this context (as a service keeps
    it between requests): its memo (``sampler.model.memo``: the proposal's fixed parts,
    about 10 s per model object here, estimated in the driver whatever the executor, from
    a fixed seed) is not estimated again."""
    from app.services import evaluations

    ctx = open_context(make_settings(data_dir, **settings))
    try:
        assert ctx.default_model_id is not None
        if model is not None:
            ctx.remember_model(ctx.default_model_id, model)
        row = evaluations.create(ctx, sut="acc", n=240, seed=5, batch_size=120)
        assert evaluations.run_job(ctx, row.id) == "done"
        return (evaluations.describe(ctx, row.id).summary or {}, ctx.executor.name,
                ctx.model(ctx.default_model_id))
    finally:
        ctx.close()


@pytest.mark.slow
def test_an_evaluation_gives_the_same_summary_inline_on_the_pool_and_on_dask(
        cluster: Any, tmp_path: Path, model_cache_dir: Path) -> None:
    """Issue 24 item 9: an evaluation job runs on the same executors as catalogues (the
    local process pool, a dask.distributed cluster) with the same result as inline."""
    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    inline, k0, model = _evaluate(data_dir, local_workers=0)
    local, k1, _ = _evaluate(data_dir, model, local_workers=2)
    dask, k2, _ = _evaluate(data_dir, model, dask_scheduler=cluster.scheduler_address)
    assert (k0, k1, k2) == ("inline", "local", "dask")
    assert inline["runs"] == 240 and inline["sut_runs"] > 0
    assert local == inline
    assert dask == inline
