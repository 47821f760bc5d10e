"""The store against SQLite and a live PostgreSQL: migrations, chunk rows (unique, all or
nothing), infinite floats, paging and filters, deletion."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import func, inspect, select, text
from sqlalchemy.exc import IntegrityError

from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow, ChunkRow, DatasetRow, ModelRow, ScenarioRow
from app.errors import NotFound
from tests.app.factories import scenario_rows


def _store(url: str) -> Database:
    db = Database(url)
    db.migrate()
    return db


def _catalogue(db: Database, cid: str = "cat-1", n: int = 10) -> None:
    with db.session() as s:
        s.add(DatasetRow(id="ds", name="d", kind="embedded", embedded=True, data_hash="h",
                         n_cutins=1, table_path="x.parquet", report={}))
        s.add(ModelRow(id="m", dataset_id="ds", is_default=True, options={}, n_components=1,
                       model_hash="mh", model_json="{}", bic_curve=[], fit_report={}))
        s.flush()
        s.add(CatalogueRow(id=cid, model_id="m", status="queued", n=n, seed=7, chunk_size=5,
                           n_chunks=(n + 4) // 5, spec={"constraints": ["ttc<3"]}))


def test_migrations_create_the_schema_and_are_idempotent(database_url: str) -> None:
    db = _store(database_url)
    db.migrate()  # a second start changes nothing
    names = set(inspect(db.engine).get_table_names())
    assert {"datasets", "models", "catalogues", "catalogue_chunks",
            "catalogue_scenarios", "alembic_version"} <= names
    with db.engine.connect() as conn:
        assert conn.execute(text("select version_num from alembic_version")).scalar() == "0007"
    db.dispose()


def test_a_chunk_is_stored_once_with_its_file(database_url: str, tmp_path: Path) -> None:
    db = _store(database_url)
    _catalogue(db)
    with db.session() as s:
        assert repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), b"abc",
                                "sha", {"ok": True})
    # the same chunk again (a second runner, a resumed job): refused, nothing duplicated
    with db.session() as s:
        assert not repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), b"abc",
                                    "sha", {})
    with db.session() as s:
        assert repo.stored_chunk_indices(s, "cat-1") == {0}
        assert repo.count_scenarios(s, "cat-1") == 5
        chunk = repo.chunk_rows(s, "cat-1")[0]
        assert (tmp_path / str(chunk.file_path)).read_bytes() == b"abc"
    # and the database itself refuses a duplicate chunk index
    with pytest.raises(IntegrityError), db.session() as s:
        s.add(ChunkRow(catalogue_id="cat-1", chunk_index=0, n_scenarios=0, diagnostics={}))
    db.dispose()


def test_a_failing_transaction_keeps_what_was_stored(database_url: str, tmp_path: Path) -> None:
    db = _store(database_url)
    _catalogue(db)
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), None, None, {})
    with pytest.raises(RuntimeError), db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 1, scenario_rows(1, 5, 5), None, None, {})
        raise RuntimeError("crash before commit")
    with db.session() as s:
        assert repo.stored_chunk_indices(s, "cat-1") == {0}
        assert repo.count_scenarios(s, "cat-1") == 5
    db.dispose()


def test_infinite_ttc_round_trips_and_filters(database_url: str, tmp_path: Path) -> None:
    db = _store(database_url)
    _catalogue(db)
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), None, None, {})
        repo.store_chunk(s, tmp_path, "cat-1", 1, scenario_rows(1, 5, 5), None, None, {})
    with db.session() as s:
        ttc = {r.idx: r.ttc for r in repo.iter_scenarios(s, "cat-1", batch=3)}
        assert list(ttc) == list(range(10))
        assert math.isinf(ttc[0]) and math.isinf(ttc[4]) and math.isinf(ttc[8])
        assert ttc[1] == 11.0 / 5.0
        # hand count: idx 1,2,3 have ttc 2.2, 2.4, 2.6 (< 2.5: 1 and 2)
        total, rows = repo.page_scenarios(s, "cat-1", repo.ScenarioFilter(ttc_max=2.5), 0, 100)
        assert total == 2 and [r.idx for r in rows] == [1, 2]
        flt = repo.ScenarioFilter(risk_min=0.03, risk_max=0.07)
        total, rows = repo.page_scenarios(s, "cat-1", flt, 1, 2)
        assert total == 5 and [r.idx for r in rows] == [4, 5]
        stats = repo.summary_statistics(s, "cat-1")
    assert stats["risk"]["count"] == 10
    assert stats["risk"]["max"] == pytest.approx(0.09)
    assert stats["risk"]["mean"] == pytest.approx(0.045)
    assert stats["ttc"]["count"] == 7  # three infinite TTCs are not in the statistics
    db.dispose()


def test_delete_removes_rows_and_files(database_url: str, tmp_path: Path) -> None:
    db = _store(database_url)
    _catalogue(db)
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), b"x", "s", {})
    with db.session() as s:
        repo.delete_catalogue(s, "cat-1")
    repo.remove_catalogue_files(tmp_path, "cat-1")
    with db.session() as s:
        assert s.scalar(select(func.count()).select_from(ScenarioRow)) == 0
        assert s.scalar(select(func.count()).select_from(ChunkRow)) == 0
        with pytest.raises(NotFound):
            repo.get_catalogue(s, "cat-1")
    assert not (tmp_path / "catalogues" / "cat-1").exists()
    db.dispose()


@pytest.mark.parametrize("n", [1, 2, 7, 40])
def test_sql_statistics_equal_numpy_on_the_finite_values(database_url: str, tmp_path: Path,
                                                         n: int) -> None:
    # issue 13: the status statistics come from SQL; numpy on the same values is the reference
    rng = np.random.default_rng(n)
    ttc = rng.exponential(2.0, n)
    ttc[::3] = math.inf  # opening gaps: not in the statistics
    risk = rng.uniform(0.0, 1.0, n)
    rows = [{"idx": i, "chunk_index": 0, "params": {}, "ttc": float(ttc[i]),
             "risk": None if i % 5 == 4 else float(risk[i]), "exposure_weight": 0.5,
             "summary": {}} for i in range(n)]
    db = _store(database_url)
    _catalogue(db, n=n)
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 0, rows, None, None, {})
    with db.session() as s:
        stats = repo.summary_statistics(s, "cat-1")
    for name, values in (("ttc", ttc), ("risk", np.array([r["risk"] for r in rows
                                                          if r["risk"] is not None]))):
        finite = values[np.isfinite(values)]
        got = stats[name]
        assert got["count_inf"] == int(np.isposinf(values).sum())
        if finite.size == 0:
            assert got == {"count": 0, "count_inf": int(np.isposinf(values).sum())}
            continue
        assert got["count"] == finite.size
        assert got["min"] == finite.min() and got["max"] == finite.max()
        assert got["mean"] == pytest.approx(finite.mean(), rel=1e-12)
        assert got["p50"] == pytest.approx(np.quantile(finite, 0.5), rel=1e-12)
        assert got["p95"] == pytest.approx(np.quantile(finite, 0.95), rel=1e-12)
        for q in (5, 25, 75):
            assert got[f"p{q:02d}"] == pytest.approx(np.quantile(finite, q / 100), rel=1e-12)
    assert stats["exposure_weight"]["p95"] == 0.5
    db.dispose()


def test_status_statistics_hand_case_and_read_per_new_chunk(
        database_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # risk of idx i is i / 100 (scenario_rows); chunk 0 holds idx 0..4, chunk 1 idx 5..9
    from app.cache import ViewCache
    from app.services import catalogues

    class Ctx:  # the part of ServiceContext the status uses
        def __init__(self) -> None:
            self.caches: dict[str, ViewCache] = {}

        def cache(self, name: str, size: int) -> ViewCache:
            return self.caches.setdefault(name, ViewCache(size))

    asked: list[object] = []
    real = repo.stat_values

    def spy(session: object, cid: str, chunks: object = None) -> object:
        asked.append(None if chunks is None else sorted(chunks))  # type: ignore[call-overload]
        return real(session, cid, chunks)  # type: ignore[arg-type]

    monkeypatch.setattr(repo, "stat_values", spy)
    db = _store(database_url)
    _catalogue(db)
    ctx = Ctx()
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 0, scenario_rows(0, 0, 5), None, None, {})
    with db.session() as s:
        first = repo.statistics_of(catalogues._stat_values(ctx, s, "cat-1"))["risk"]  # type: ignore[arg-type]
    # 0, .01, .02, .03, .04: p25 at position 1 -> 0.01; p05 at 0.2 -> 0.002
    assert first["count"] == 5 and first["p50"] == pytest.approx(0.02)
    assert first["p25"] == pytest.approx(0.01) and first["p05"] == pytest.approx(0.002)
    with db.session() as s:
        repo.store_chunk(s, tmp_path, "cat-1", 1, scenario_rows(1, 5, 5), None, None, {})
    with db.session() as s:
        both = repo.statistics_of(catalogues._stat_values(ctx, s, "cat-1"))  # type: ignore[arg-type]
    # 0 .. 0.09: p50 at position 4.5 -> 0.045; p95 at 8.55 -> 0.0855; mean 0.045
    assert both["risk"]["count"] == 10 and both["risk"]["p50"] == pytest.approx(0.045)
    assert both["risk"]["p95"] == pytest.approx(0.0855)
    assert both["risk"]["mean"] == pytest.approx(0.045)
    # ttc of idx 0, 4, 8 is +inf (scenario_rows): not in the finite statistics
    assert both["ttc"]["count_inf"] == 3 and both["ttc"]["count"] == 7
    assert asked == [None, [1]]  # all at first, then only the chunk stored since
    db.dispose()


def test_chunk_stat_blob_equals_the_row_scan_and_old_chunks_are_scanned(
        database_url: str, tmp_path: Path) -> None:
    from sqlalchemy import update as sql_update

    db = _store(database_url)
    _catalogue(db)
    with db.session() as s:
        for c in range(3):
            repo.store_chunk(s, tmp_path, "cat-1", c, scenario_rows(c, 4 * c, 4), None, None,
                             {})
    with db.session() as s:
        chunk_of, blobs = repo.stat_values(s, "cat-1")
        scan_of, scanned = repo._scan_stat_values(s, "cat-1", [0, 1, 2])
    order, scan_order = np.argsort(chunk_of, kind="stable"), np.argsort(scan_of, kind="stable")
    np.testing.assert_array_equal(chunk_of[order], scan_of[scan_order])
    np.testing.assert_array_equal(blobs[order], scanned[scan_order])  # NaN = NaN, inf = inf
    assert np.isinf(blobs).any() and blobs.shape == (12, len(repo.STAT_COLUMNS))
    # a chunk stored before the blob (or with other columns) is read from its rows
    with db.session() as s:
        s.execute(sql_update(ChunkRow).where(ChunkRow.chunk_index == 1)
                  .values(stat_values=None))
        s.execute(sql_update(ChunkRow).where(ChunkRow.chunk_index == 2)
                  .values(stat_columns=["risk"]))
    with db.session() as s:
        mixed_of, mixed = repo.stat_values(s, "cat-1")
        only_1, values_1 = repo.stat_values(s, "cat-1", [1])
    m_order = np.argsort(mixed_of, kind="stable")
    np.testing.assert_array_equal(mixed[m_order], scanned[scan_order])
    np.testing.assert_array_equal(only_1, [1, 1, 1, 1])
    np.testing.assert_array_equal(values_1, scanned[scan_of == 1])
    db.dispose()
