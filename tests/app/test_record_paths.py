"""Issue 13: one vector -> scored record. The same vectors scored through POST /scenarios,
a catalogue chunk and ``scengen sample --score`` give the same records."""

from __future__ import annotations

import importlib
import json
import math
from pathlib import Path
from typing import Any

import pytest

from app.cli import main
from app.db.models import ScenarioRow
from app.jobs import chunk as chunk_module
from app.jobs.chunk import CatalogueSpec, compute_chunk
from app.services.catalogues import record_of
from riskcore.criticality import CRITICALITY_FIELDS
from sampler.scenario.record import ScenarioRecord

N, SEED = 4, 5
CONSTRAINTS = ["ttc<3"]


def _ctx(client: Any) -> Any:
    return client.app.state.ctx


@pytest.mark.slow
def test_route_job_and_cli_give_the_same_record(client: Any, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    # the route
    r = client.post("/scenarios", json={"n": N, "seed": SEED, "constraints": CONSTRAINTS,
                                        "sampler": "rejection", "score": True,
                                        "wagner_scan": True})
    assert r.status_code == 200, r.text
    route = [ScenarioRecord.model_validate(item) for item in r.json()["scenarios"]]
    assert [rec.index for rec in route] == list(range(N))
    assert all(rec.error is None and rec.class_ is not None for rec in route)

    # a catalogue chunk drawing the same vectors: chunk 0 sampled with the request's seed
    ctx = _ctx(client)
    model_json = ctx.model(ctx.default_model_id).to_json()
    monkeypatch.setattr(chunk_module, "chunk_seed", lambda seed, index: SEED)
    spec = CatalogueSpec(n=N, seed=123, chunk_size=N, model_json=model_json,
                         constraints=tuple(CONSTRAINTS), method="rejection",
                         store_trajectories=False, wagner_scan=True)
    result = compute_chunk(spec, 0)
    job = [record_of(ScenarioRow(**row)) for row in result.rows]

    # the CLI on the same model
    model_path = tmp_path / "model.json"
    model_path.write_text(model_json)
    out = tmp_path / "scored.jsonl"
    assert main(["sample", str(model_path), "-c", *CONSTRAINTS, "-n", str(N), "--seed",
                 str(SEED), "--sampler", "rejection", "--score", "--wagner-scan", "-o", str(out),
                 "-q"]) == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    cli = [ScenarioRecord.model_validate({k: v for k, v in line.items()
                                          if k not in ("derived", "log_density")})
           for line in lines]

    assert cli == route  # with each vector's data support
    assert all(rec.support in ("inside", "near", "extrapolated") for rec in route)
    # catalogue rows do not store the data support (yet): the rest of the record is equal
    support = {"support", "support_distance", "support_excess", "support_nearest",
               "density_pct", "support_outside"}
    assert [rec.model_dump(exclude=support) for rec in job] == \
        [rec.model_dump(exclude=support) for rec in route]
    for rec in route:  # and the record is what it claims, by hand
        assert rec.ttc == pytest.approx(rec.params["gap"] / rec.params["dv"], rel=1e-12)
        assert rec.ttc < 3.0 and rec.risk_peak is not None and 0.0 <= rec.risk_peak <= 1.0
        assert rec.r_dep_cross is not None  # Wagner's scan asked for on all three paths
        assert rec.a_req is not None and rec.btn == pytest.approx(rec.a_req / (0.774 * 9.81))
        assert rec.ttr_true is not None and (math.isinf(rec.ttr_true) or rec.ttr_true >= 0.0)


def test_a_refused_vector_is_a_row_with_an_error_not_a_failed_chunk(
        client: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    ctx = _ctx(client)
    spec = CatalogueSpec(n=3, seed=1, chunk_size=3,
                         model_json=ctx.model(ctx.default_model_id).to_json(),
                         constraints=tuple(CONSTRAINTS), method="rejection")
    real = chunk_module.score_rows

    def refuse_second(table: Any, **kwargs: Any) -> Any:
        table = table.copy()
        table.loc[1, "p_y1"] = 0.0  # the builder refuses: the cutter would not change lanes
        return real(table, **kwargs)

    monkeypatch.setattr(chunk_module, "score_rows", refuse_second)
    result = compute_chunk(spec, 0)
    errors = [row["error"] for row in result.rows]
    assert errors[0] is None and errors[2] is None
    assert errors[1] is not None and errors[1].startswith("build: ") and "p_y1" in errors[1]
    assert result.rows[1]["btn"] is None and result.rows[0]["btn"] is not None
    from app.db import chunkfile

    assert result.blob is not None
    path = Path(ctx.data_dir) / "refused.jsonl.gz"
    path.write_bytes(result.blob)
    stored = list(chunkfile.read_scenarios(path))
    assert stored[1] is None and stored[0] is not None and stored[2] is not None


def test_record_row_and_migration_carry_every_criticality_field() -> None:
    migration = importlib.import_module("app.migrations.versions.0004_criticality")

    names = list(CRITICALITY_FIELDS)
    record_fields = [f.alias or k for k, f in ScenarioRecord.model_fields.items()]
    assert record_fields[record_fields.index("t_p"):][:len(names)] == names
    columns = {c.name: c for c in ScenarioRow.__table__.columns}
    kinds = {"float": "FLOAT", "bool": "BOOLEAN", "str": "TEXT"}
    for name, spec in CRITICALITY_FIELDS.items():
        assert str(columns[name].type) == kinds[spec.kind] and columns[name].nullable
    assert [n for n, _ in migration.COLUMNS] == names


@pytest.mark.slow
def test_the_pool_scores_parts_as_the_request_itself_does() -> None:
    # POST /scenarios splits its vectors over the executor (LocalPoolExecutor.map)
    import pandas as pd

    from app.jobs.executors import InlineExecutor, LocalPoolExecutor
    from sampler.scenario.scoring import score_part
    from tests.sampler.factories import base_params

    table = pd.DataFrame([base_params(gap=6.0 + i, dv=2.0) for i in range(4)])
    parts = [table.iloc[:2].reset_index(drop=True), table.iloc[2:].reset_index(drop=True)]
    args = (parts, [0, 2], [[0.1, 0.1], [0.1, 0.1]], [{"lane_width": 3.5}] * 2)
    pool = LocalPoolExecutor(1)
    try:
        pooled = pool.map(score_part, *args)
        later = pool.map_later(score_part, *args)  # submitted now, gathered below
        gathered = later()
    finally:
        pool.close()
    inline = InlineExecutor().map(score_part, *args)
    assert gathered == pooled == InlineExecutor().map_later(score_part, *args)()
    assert pooled == inline and [r.index for p in pooled for r in p] == [0, 1, 2, 3]
    assert all(r.class_ is not None for p in pooled for r in p)


def loaded_kernels(_: object) -> int:
    """In a pool worker: how many compiled signatures the criticality record's closed-loop
    kernel holds (0 until a scenario was scored in this process; for the test only). Not
    the batched Wagner kernel: the scan is opt-in since issue 25, a default record does
    not load it."""
    from riskcore.criticality import kernels as _criticality_kernels

    return len(_criticality_kernels.drive.signatures)


@pytest.mark.slow
def test_warm_loads_the_kernels_in_the_pool_workers_and_inline_does_nothing() -> None:
    from app.jobs.executors import InlineExecutor, LocalPoolExecutor

    assert InlineExecutor().warm() is None
    pool = LocalPoolExecutor(1)
    try:
        thread = pool.warm()
        thread.join(timeout=120)
        assert not thread.is_alive()
        assert pool.map(loaded_kernels, [None]) == [1]
    finally:
        pool.close()
    pool = LocalPoolExecutor(1)
    try:  # without the warm-up a fresh worker has loaded nothing
        assert pool.map(loaded_kernels, [None]) == [0]
    finally:
        pool.close()


def loaded_kernels_held(_: object) -> tuple[int, int]:
    """(pid, loaded_kernels) after holding a moment, so that the other idle worker takes
    the next task."""
    import os
    import time

    time.sleep(0.5)
    return os.getpid(), loaded_kernels(None)


@pytest.mark.slow
def test_warm_reaches_every_worker_of_the_pool() -> None:
    """Issue 25 item 4: a worker still starting while the other took every warm-up task
    made the first request wait; after the warm-up each worker has its kernels."""
    from app.jobs.executors import LocalPoolExecutor

    pool = LocalPoolExecutor(2)
    try:
        pool.warm().join(timeout=600)
        seen: dict[int, int] = {}
        for _ in range(20):
            seen.update(pool.map(loaded_kernels_held, [None, None]))
            if len(seen) == 2:
                break
        assert len(seen) == 2 and set(seen.values()) == {1}, seen
    finally:
        pool.close()


@pytest.mark.slow
def test_warm_start_estimates_the_default_regions_model_figures(model_cache_dir: Path,
                                                                tmp_path: Path) -> None:
    from app.services.store import open_context
    from tests.app.factories import copy_model_cache, make_settings

    data_dir = tmp_path / "data"
    copy_model_cache(model_cache_dir, data_dir)
    ctx = open_context(make_settings(data_dir))
    try:
        assert ctx.default_model_id is not None
        model = ctx.model(ctx.default_model_id)
        assert "_scengen_memo" not in model.__dict__  # nothing estimated yet
        thread = ctx.warm_start()
        assert ctx.warming
        thread.join(timeout=300)
        assert not ctx.warming  # /health now says "ok"
        kinds = {key[0] for key in model.__dict__["_scengen_memo"]}
        assert model.bootstrap_  # the default model has replicates (n_bootstrap 100) ...
        assert {"p_bounds", "pooled_interval"} <= kinds  # ... so its model interval too
        assert "support" in model.__dict__["_scengen_memo"]  # issue 25's data-support index
    finally:
        ctx.close()
