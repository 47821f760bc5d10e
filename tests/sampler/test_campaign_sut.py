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
    (equal to a direct ``simulate(risk=True)`` of the same batch); without it the risk
    fields are NaN and the outcomes are the same."""
    from riskcore.sut import simulate
    from sampler.scenario import cutin_batch

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
    rows = np.flatnonzero(ok)
    direct = simulate(make_sut("acc"), cutin_batch(x[rows], lane_width=3.75), seeds=seeds[rows],
                      risk=True)
    assert risky.r_dep_peak[rows].tolist() == direct.r_dep_peak.tolist()


def _runner_reference(sut: str, x: np.ndarray, seeds: np.ndarray, settings: SimSettings,
                      lane: float) -> dict[str, np.ndarray]:
    """The runner as it was written first: ``ok`` from one build of every row, then a
    second build of the buildable rows by ``cutin_batch`` (its own grid) and simulate."""
    from riskcore.sut import RUN_FIELDS, simulate
    from sampler.scenario import cutin_batch, cutin_tracks

    ok = cutin_tracks(x, lane_width=lane).ok
    rows = np.flatnonzero(ok)
    batch = cutin_batch(x[rows], lane_width=lane)
    runs = simulate(make_sut(sut), batch, seeds=seeds[rows], settings=settings)
    out: dict[str, np.ndarray] = {"buildable": ok}
    for name in RUN_FIELDS:
        out[name] = np.asarray(getattr(runs, name))
    out["rows"] = rows
    out["grid_end"] = batch.t[-1:]
    return out


def test_the_runner_equals_two_builds_and_simulate_bit_for_bit() -> None:
    """Model draws with refused rows among them (one with the longest script, so the
    buildable rows' grid is shorter than that of all rows, and runs going past its end):
    every field of every run equals the reference's, bit for bit."""
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
        ref = _runner_reference(sut, x, seeds, st, 3.6)
        rows = ref.pop("rows")
        grid_end = float(ref.pop("grid_end")[0])
        assert out.buildable.tolist() == ref.pop("buildable").tolist()
        assert 120 <= rows.size <= 290
        assert not out.buildable[[11, 12, 13]].any()
        assert (out.end[~out.buildable] == "not_buildable").all()
        for name, want in ref.items():
            got = np.asarray(getattr(out, name))[rows]
            assert got.tobytes() == want.astype(got.dtype).tobytes(), (sut, name)
        if sut == "acc":  # some runs outlive the buildable rows' grid
            assert grid_end < 2.5 + 60.0 and (ref["end_time"] > grid_end).sum() >= 1
