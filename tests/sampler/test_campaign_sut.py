"""sampler.campaign.sut_runner: a system under test in riskcore's simulator.

Reference: the criticality quantities computed straight from the vectors
(``sampler.region.criticality_quantities``, its own compiled kernels): the scripted ego
(riskcore's ``none`` SUT keeps its speed) collides exactly where ``none_collision`` says.
"""

from __future__ import annotations

import numpy as np

from datasets import PARAM_NAMES
from riskcore.sut import SimSettings, make_sut
from sampler import CutInGMM
from sampler.campaign import evaluate, sut_runner
from sampler.region import criticality_quantities
from tests.sampler.factories import synthetic_parameter_table


def _critical_rows(n: int, seed: int) -> np.ndarray:
    x = synthetic_parameter_table(n, seed=seed)[list(PARAM_NAMES)].to_numpy(
        dtype=np.float64).copy()
    closing = np.arange(n) % 2 == 0
    x[:, 6] = np.where(closing, np.abs(x[:, 6]) + 2.0, -np.abs(x[:, 6]) - 2.0)
    x[:, 2] = np.where(closing, x[:, 2], np.abs(x[:, 2]))  # the opening ones never brake
    x[:, 7] = np.linspace(0.5, 25.0, n)  # from hopeless to harmless gaps
    return x


def test_none_collides_where_the_scripted_ego_does() -> None:
    x = _critical_rows(40, 2)
    runner = sut_runner(lambda: make_sut("none"), careful=True, lane_width=3.75)
    out = runner(x, np.arange(40, dtype=np.uint64))
    ref = criticality_quantities(x, 3.75, with_ttr=False)["none_collision"]
    ok = np.isfinite(ref)
    assert ok.sum() >= 35
    assert out.collided[ok].tolist() == (ref[ok] == 1).tolist()
    assert 5 < out.collided.sum() < 35  # both outcomes occur
    # the careful driver never does worse than doing nothing here
    assert set(out.vs_careful[ok].tolist()) <= {"worse", "same"}
    # worse: collides where the careful driver does not, or hits harder (0.01 m/s)
    harder = out.impact_speed > out.careful_impact_speed + 0.01
    assert (out.vs_careful[ok] == "worse").tolist() == (
        out.collided[ok] & (~out.careful_collided[ok] | harder[ok])).tolist()


def test_refused_rows_are_not_run_and_do_not_collide() -> None:
    x = _critical_rows(3, 4)
    x[1, 0] = 0.0  # no lane change
    out = sut_runner(make_sut("none"), careful=False, lane_width=3.75)(
        x, np.arange(3, dtype=np.uint64))
    assert out.buildable.tolist() == [True, False, True]
    assert not out.collided[1] and out.end[1] == "not_buildable"


def test_a_campaign_with_a_sut_is_deterministic() -> None:
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))
    runner = sut_runner(lambda: make_sut("acc", a_min=-3.0), careful=False,
                        settings=SimSettings(t_max=30.0))
    one = evaluate(model, runner, n=200, seed=1, batch_size=100, bootstrap=False)
    two = evaluate(model, runner, n=200, seed=1, batch_size=100, bootstrap=False)
    assert one.summary() == two.summary()
    assert one.summary()["sut_runs"] > 30
    rec = one.records()[0]
    assert {"collided", "min_ttc", "must_avoid", "violation", "vs_careful", "weight"} <= set(rec)


def test_risk_of_the_suts_own_drive_is_opt_in() -> None:
    """``risk=True`` passes through to riskcore's simulator: the SUT's r_dep peak per run
    (equal to a direct ``simulate(risk=True)`` of each row alone on its own grid); without
    it the risk fields are NaN and the outcomes are the same."""
    x = _critical_rows(6, 3)
    seeds = np.arange(6, dtype=np.uint64)
    plain = sut_runner(lambda: make_sut("acc"), careful=False, lane_width=3.75)(x, seeds)
    risky = sut_runner(lambda: make_sut("acc"), careful=False, lane_width=3.75,
                       risk=True)(x, seeds)
    assert np.isnan(plain.r_dep_peak).all()
    ok = risky.buildable
    assert ok.sum() >= 4
    assert np.isfinite(risky.r_dep_peak[ok]).all()
    assert ((risky.r_dep_peak[ok] >= 0) & (risky.r_dep_peak[ok] <= 1)).all()
    assert risky.collided.tolist() == plain.collided.tolist()
    ref = _alone("acc", x, seeds, SimSettings(), 3.75, risk=True)
    assert risky.r_dep_peak[ref["rows"]].tolist() == ref["r_dep_peak"].tolist()


def _alone(sut: str, x: np.ndarray, seeds: np.ndarray, settings: SimSettings, lane: float,
           risk: bool = False) -> dict[str, np.ndarray]:
    """The reference: every buildable row simulated alone, on its own grid (its script's
    end plus 3 s, rounded up to a whole 5 s: ``own_grid_steps``, checked by hand in
    test_cutin_batch.py), built by ``cutin_batch``."""
    from riskcore.sut import RUN_FIELDS, simulate
    from sampler.scenario import cutin_batch, cutin_tracks
    from sampler.scenario.batch import own_grid_steps

    ok = cutin_tracks(x, lane_width=lane).ok
    rows = np.flatnonzero(ok)
    steps = own_grid_steps(x)
    runs = [simulate(make_sut(sut), cutin_batch(x[i:i + 1], lane_width=lane,
                                                duration=float(steps[i]) * 0.1),
                     seeds=seeds[i:i + 1], settings=settings, risk=risk) for i in rows]
    out: dict[str, np.ndarray] = {"buildable": ok, "rows": rows}
    for name in RUN_FIELDS:
        out[name] = np.concatenate([np.asarray(getattr(r, name)) for r in runs])
    return out


def test_the_runner_equals_each_row_simulated_alone_bit_for_bit() -> None:
    """Model draws with refused rows among them (one with the longest script, runs going
    past their script's end + 3 s): every field of every run equals that of its row
    simulated alone on its own grid, bit for bit."""
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=5))
    rng = np.random.default_rng(4)
    x = model.params_matrix(model.sample(300, rng))
    x[::37, 0] = 0.0
    x[11, 1], x[11, 0] = 30.0, 1e-4  # the longest script, never reaches the marking
    x[12, 6] = -80.0  # ego speed <= 0
    x[13, 4] = np.nan
    seeds = np.asarray(rng.integers(0, 2**63, size=x.shape[0], dtype=np.uint64))
    for sut, st in (("acc", SimSettings(t_max=60.0)), ("none", SimSettings(t_max=20.0))):
        out = sut_runner(make_sut(sut), careful=False, settings=st, lane_width=3.6)(
            x, seeds)
        ref = _alone(sut, x, seeds, st, 3.6)
        rows = ref.pop("rows")
        assert out.buildable.tolist() == ref.pop("buildable").tolist()
        assert 120 <= rows.size <= 290
        assert not out.buildable[[11, 12, 13]].any()
        assert (out.end[~out.buildable] == "not_buildable").all()
        for name, want in ref.items():
            got = np.asarray(getattr(out, name))[rows]
            assert got.tobytes() == want.astype(got.dtype).tobytes(), (sut, name)
        if sut == "acc":  # some runs outlive their script's end + 3 s
            settle = 2.5 + np.maximum(2.0 * x[rows, 1], x[rows, 3] + x[rows, 4])
            assert (ref["end_time"] > settle + 3.0).sum() >= 5


#: model draws (rounded) whose acc run (k2=0.5, t_max 40 s) settles 13-24 s into the
#: run, well after the cutter's script ended + 3 s
_OUTLIVING = np.array([[-0.019, 2.583, 0.878, -2.498, 3.831, 29.07, 4.634, 47.87],
                       [0.012, 3.954, -0.169, 1.695, 5.489, 25.129, 1.225, 47.264],
                       [-0.059, 2.021, 0.373, -1.142, 2.876, 18.0, 4.288, 56.501],
                       [0.036, 1.939, -1.061, 1.273, 11.205, 30.941, -3.756, 36.279]])


def test_a_runs_outcome_does_not_depend_on_its_batch_mates() -> None:
    """A run outliving its script's end + 3 s gives the same outcome, every field (the
    careful driver's too) bit for bit, alone and in blocks with other rows: one with a
    much longer lane change (12 s: a longer grid), critical ones, in any position. (On
    one grid per block the cutter was continued from the block's last step: the low
    bits of min_gap, min_thw, min_ttc, max_decel changed with the block.)"""
    long = _OUTLIVING[0].copy()
    long[1] = 12.0
    mates = _critical_rows(12, 6)
    runner = sut_runner(lambda: make_sut("acc", k2=0.5), careful=True,
                        settings=SimSettings(t_max=40.0), lane_width=3.75)
    for i, row in enumerate(_OUTLIVING):
        seed = np.uint64(1000 + i)
        alone = runner(row[None], np.array([seed]))
        assert alone.buildable[0] and alone.end[0] == "settled"
        settle = 2.5 + max(2.0 * row[1], row[3] + row[4])
        assert alone.end_time[0] > settle + 3.0
        for block, at in ((np.stack([long, row]), 1), (np.stack([row, long]), 0),
                          (np.vstack([mates[:5], row[None], long[None], mates[5:]]), 5),
                          (np.vstack([_OUTLIVING, mates]), i)):
            seeds = np.arange(block.shape[0], dtype=np.uint64)
            seeds[at] = seed
            out = runner(block, seeds)
            for name, want in alone.arrays.items():
                got = np.asarray(out.arrays[name])[at:at + 1]
                assert got.tobytes() == want.astype(got.dtype).tobytes(), (i, at, name)
