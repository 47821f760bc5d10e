"""Synthetic highD recordings: extraction finds the generated cut-ins and recovers them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from datasets.extract import ExtractionResult, extract_cutins
from datasets.highd import read_highd, road_frame
from datasets.synth import generate_recording, write_synthetic

# stated tolerances of the recovery (docs/datasets.md)
TOL_ABS = {"gap": 0.5, "dv": 0.3, "p_y1": 0.003, "p_v0": 0.2, "p_a2": 0.2, "p_a3": 0.2,
           "t_start": 0.1, "t_cross": 0.05}
TOL_REL = {"p_t": 0.10, "p_y1": 0.05}


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame,
                                                                  ExtractionResult]:
    d = tmp_path_factory.mktemp("synth")
    write_synthetic(d, seed=11, minutes=5.0, vehicles=380)
    truth = pd.read_csv(d / "01_groundtruth_SYNTHETIC.csv", dtype={"event_id": str},
                        keep_default_na=False, na_values=[""])
    return d, truth, extract_cutins(d, "highd")


@pytest.mark.slow
def test_labelled_synthetic_everywhere(synthetic: tuple[Path, pd.DataFrame,
                                                        ExtractionResult]) -> None:
    d, truth, res = synthetic
    rec = read_highd(d / "01")
    assert rec.is_synthetic
    assert rec.recording_meta["month"].iloc[0] == "SYNTHETIC"
    assert "SYNTHETIC DATA" in (d / "SYNTHETIC.md").read_text()
    assert truth["synthetic"].all()
    assert (res.table["source"] == "synthetic:01").all()


def test_traffic_is_plausible(synthetic: tuple[Path, pd.DataFrame, ExtractionResult]) -> None:
    d, _, _ = synthetic
    rec = read_highd(d / "01")
    road = road_frame(rec)
    v = np.hypot(road["vx"], road["vy"])
    assert 20.0 < float(np.median(v)) < 35.0
    assert float(np.percentile(v, 1)) > 10.0 and float(v.max()) < 48.0
    assert set(road["lane_id"].unique()) == {2, 3, 4, 6, 7, 8}  # 3 lanes per direction
    assert set(rec.tracks_meta["drivingDirection"]) == {1, 2}
    # bumper-to-bumper gaps to the preceding vehicle stay positive
    dhw = rec.tracks["dhw"].to_numpy()
    has = rec.tracks["precedingId"].to_numpy() != 0
    assert (dhw[has] > 0).mean() > 0.999
    assert 250 < len(rec.tracks_meta) <= 380


def test_extraction_finds_the_cut_ins_and_no_false_ones(
    synthetic: tuple[Path, pd.DataFrame, ExtractionResult]
) -> None:
    _, truth, res = synthetic
    true_ids = set(truth.loc[truth["is_cutin"], "event_id"])
    assert len(true_ids) >= 10
    found = set(res.table["event_id"])
    assert found <= true_ids, f"false cut-ins: {sorted(found - true_ids)}"
    assert len(found & true_ids) >= 0.95 * len(true_ids)
    # lane changes with nobody behind are in the truth but are not cut-ins
    assert (~truth["is_cutin"]).sum() >= 1


def test_each_cut_in_recovered_within_tolerances(
    synthetic: tuple[Path, pd.DataFrame, ExtractionResult]
) -> None:
    _, truth, res = synthetic
    m = truth[truth["is_cutin"]].merge(res.table, on="event_id", suffixes=("_true", ""))
    assert len(m) >= 10
    for col, tol in TOL_ABS.items():
        err = np.abs(m[col] - m[f"{col}_true"])
        assert err.max() <= tol, f"{col}: max error {err.max():.4f} > {tol}"
    for col, tol in TOL_REL.items():
        err = np.abs(m[col] / m[f"{col}_true"] - 1.0)
        assert err.max() <= tol, f"{col}: max relative error {err.max():.4f} > {tol}"
    err_a1 = np.abs(m["p_a1"] - m["p_a1_true"])
    assert (err_a1 <= 0.1 + 0.1 * np.abs(m["p_a1_true"])).all()
    assert (m["side"] == m["side_true"]).all()
    assert (m["ego_id"].astype(int) == m["ego_id_true"]).all()
    assert np.allclose(m["lane_width"], m["lane_width_true"], atol=0.01)


def test_same_seed_same_recording() -> None:
    a = generate_recording(3, minutes=0.5, vehicles=40)
    b = generate_recording(3, minutes=0.5, vehicles=40)
    c = generate_recording(4, minutes=0.5, vehicles=40)
    pd.testing.assert_frame_equal(a.recording.tracks, b.recording.tracks, check_exact=True)
    pd.testing.assert_frame_equal(a.truth, b.truth, check_exact=True)
    assert not a.recording.tracks.equals(c.recording.tracks)
