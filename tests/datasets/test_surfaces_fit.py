"""Surface fitting: hand-computed ML cases, filling, mirror symmetry, seeded statistics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from datasets.errors import DatasetError
from datasets.surfaces_fit import (
    SurfaceGrid,
    fit_surface,
    fit_surfaces,
    input_samples,
    trajectories_from_egocentric,
    write_surfaces,
)
from riskcore.surfaces import InputSurfaces

V_AXIS = np.array([10.0, 20.0, 30.0])
X_AXIS = np.array([-1.0, 0.0, 1.0])


def test_ml_gaussian_by_hand_when_all_samples_coincide() -> None:
    # all samples at one point: every node weighs them equally -> plain ML estimates
    y = np.array([1.0, 2.0, 3.0, 4.0])
    f = fit_surface(np.full(4, 20.0), np.zeros(4), y, V_AXIS, X_AXIS, min_count=1,
                    std_floor=0.01)
    assert f["mean"] == pytest.approx(np.full((3, 3), 2.5))
    assert f["std"] == pytest.approx(np.full((3, 3), np.sqrt(1.25)))  # ML: divide by n
    # kernel-weighted count: 4 samples, weight exp(-d^2/2) with d in grid steps
    w = np.exp(-0.5 * (np.array([1.0, 0.0, 1.0])[:, None] ** 2 + np.array([1.0, 0.0, 1.0]) ** 2))
    assert f["count"] == pytest.approx(4.0 * w)


def test_sparse_nodes_are_filled_from_the_nearest_node() -> None:
    rng = np.random.default_rng(1)
    n = 400
    v0 = rng.normal(10.0, 0.5, n)
    x0 = rng.normal(-1.0, 0.05, n)
    y = rng.normal(-0.5, 0.2, n)
    va = np.array([10.0, 20.0, 30.0, 40.0, 50.0])
    xa = np.array([-1.0, 0.0, 1.0, 2.0, 3.0])
    f = fit_surface(v0, x0, y, va, xa, min_count=30, std_floor=0.01)
    assert f["count"][0, 0] > 300
    assert f["mean"][0, 0] == pytest.approx(-0.5, abs=0.05)
    # counts ~ 400 exp(-d^2 / 2) (d in grid steps): observed up to d^2 = 5, e.g. (1, 2);
    # (4, 4) is far: filled from its nearest observed nodes (1, 2) or (2, 1), at d^2 = 13
    assert f["count"][1, 2] > 30 and f["count"][2, 2] == 0.0 and f["count"][4, 4] == 0.0
    assert f["mean"][4, 4] in (f["mean"][1, 2], f["mean"][2, 1])
    assert f["std"][4, 4] in (f["std"][1, 2], f["std"][2, 1])


def test_std_floor_and_no_data_error() -> None:
    f = fit_surface(np.full(50, 20.0), np.zeros(50), np.full(50, 0.3), V_AXIS, X_AXIS,
                    min_count=3, std_floor=0.05)
    assert (f["std"] == 0.05).all()
    with pytest.raises(DatasetError, match="kernel-weighted count"):
        fit_surface(np.array([20.0]), np.array([0.0]), np.array([1.0]), V_AXIS, X_AXIS,
                    min_count=30, std_floor=0.01)


def test_seeded_statistics_linear_mean() -> None:
    # y ~ N(0.8 x0 + 0.01 v0, 0.3): the local-linear fit recovers mean and std everywhere
    rng = np.random.default_rng(7)
    n = 40_000
    v0 = rng.uniform(0.0, 40.0, n)
    x0 = rng.uniform(-3.0, 3.0, n)
    y = 0.8 * x0 + 0.01 * v0 + rng.normal(0.0, 0.3, n)
    va = np.arange(0.0, 40.1, 5.0)
    xa = np.arange(-3.0, 3.01, 0.5)
    f = fit_surface(v0, x0, y, va, xa, min_count=30, std_floor=0.01)
    expect = 0.8 * xa[None, :] + 0.01 * va[:, None]
    assert np.abs(f["mean"] - expect).max() < 0.06
    assert np.abs(f["std"] - 0.3).max() < 0.03


def test_input_samples_by_hand() -> None:
    # v = 20 + 0.5 t, psi = 0.01 t: a0 = a_bar = 0.5, w0 = w_bar = 0.01 exactly
    t = np.arange(0.0, 5.0, 0.05)
    traj = pd.DataFrame({"track_id": "a", "t": t, "v": 20 + 0.5 * t, "psi": 0.01 * t})
    acc, turn = input_samples(traj)
    # 10 Hz grid 0..4.9 s (50 points); k = 1..39: one step back, 10 steps (1 s) ahead
    assert len(acc) == len(turn) == 39
    assert acc["x0"].to_numpy() == pytest.approx(0.5)
    assert acc["y"].to_numpy() == pytest.approx(0.5)
    assert turn["x0"].to_numpy() == pytest.approx(0.01)
    assert turn["y"].to_numpy() == pytest.approx(0.01)
    # a track without heading feeds the acceleration surface only
    acc2, turn2 = input_samples(traj.assign(psi=np.nan))
    assert len(acc2) == 39 and len(turn2) == 0


def _traj(seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    parts = []
    for k in range(60):
        t = np.arange(0.0, 20.0, 0.1)
        v = rng.uniform(15, 35) + np.cumsum(rng.normal(0, 0.05, t.size))
        w = 0.03 * np.sin(t * rng.uniform(0.2, 1.0)) * rng.choice([-1, 1])
        parts.append(pd.DataFrame({"track_id": str(k), "t": t, "v": v,
                                   "psi": np.cumsum(w) * 0.1}))
    return pd.concat(parts, ignore_index=True)


def test_fit_surfaces_format_and_mirror_symmetry(tmp_path: Path) -> None:
    grid = SurfaceGrid(min_count=10)
    out = fit_surfaces(_traj(3), grid=grid, source="unit test")
    assert out["format"] == "scengen.input-surfaces/1" and out["interim"] is False
    turn = out["turn"]
    x0 = np.array(turn["x0"])
    np.testing.assert_array_equal(x0, -x0[::-1])
    mean = np.array(turn["mean"])
    std = np.array(turn["std"])
    np.testing.assert_array_equal(mean, -mean[:, ::-1])
    np.testing.assert_array_equal(std, std[:, ::-1])
    path = write_surfaces(out, tmp_path / "s.json")
    loaded = InputSurfaces.load(path)
    assert loaded.source == "unit test"
    m1, s1 = loaded.turn(np.array([25.0]), np.array([0.03]))
    m2, s2 = loaded.turn(np.array([25.0]), np.array([-0.03]))
    assert m1[0] == pytest.approx(-m2[0]) and s1[0] == pytest.approx(s2[0])
    assert json.loads(path.read_text())["accel"]["v0"][0] == 0.0


def test_surfaces_from_egocentric_events() -> None:
    from datasets.embedded import load_default_events

    ev = load_default_events()
    some = ev[ev["event_id"].isin(ev["event_id"].unique()[:40])]
    traj = trajectories_from_egocentric(some)
    assert set(traj["track_id"].str.split("/").str[1]) == {"ego", "target"}
    assert traj.loc[traj["track_id"].str.endswith("/ego"), "psi"].isna().all()
    out = fit_surfaces(traj, grid=SurfaceGrid(min_count=10))
    InputSurfaces.from_dict(out)
    # the packaged riskcore default is ours: fitted, not interim
    default = InputSurfaces.load()
    assert default.interim is False and "TNO" in default.source
