"""The reference drivers run by the simulator give the criticality record's outcomes.

The record (riskcore.criticality) keeps its own fast kernels; these tests are the proof
that they and the simulator are one model: on a ttc < 3 sample of generated cut-ins,
``none``, ``r157_cc_conflict`` (the record's default rule), ``r157_cc`` (JRC-FSM rule =
the record with ``critical_ttc = 2``) and ``rss`` give the same collisions, impact speeds
and smallest gaps, to 1e-9 (measured: ~1e-11).
"""

from __future__ import annotations

import numpy as np
import pytest

from riskcore.criticality import CriticalitySettings, evaluate_criticality
from riskcore.scenario import ConcreteScenario
from riskcore.sut import CutInBatch, make_sut, simulate
from sampler import BuilderError, build_scenario

TOL = 1e-9


def _ttc3_sample(n: int, seed: int) -> list[ConcreteScenario]:
    """Generated cut-ins with TTC = gap / dv < 3 s at the crossing (uniform draws)."""
    rng = np.random.default_rng(seed)
    out: list[ConcreteScenario] = []
    while len(out) < n:
        dv = rng.uniform(0.5, 10.0)
        p = {"p_y1": rng.choice([-1, 1]) * rng.uniform(0.05, 0.2),
             "p_t": rng.uniform(1.5, 3.0), "p_a1": rng.uniform(-3.0, 1.0),
             "p_a2": rng.uniform(-1.0, 3.0), "p_a3": rng.uniform(0.0, 3.0),
             "p_v0": rng.uniform(10.0, 35.0), "dv": dv, "gap": rng.uniform(0.2, 3.0) * dv}
        try:
            out.append(build_scenario(p))
        except BuilderError:
            continue
    return out


@pytest.fixture(scope="module")
def scenarios() -> list[ConcreteScenario]:
    return _ttc3_sample(120, 7)


@pytest.mark.parametrize(("sut", "field", "critical_ttc"), [
    ("none", "none", float("inf")),
    ("r157_cc_conflict", "r157_cc", float("inf")),
    ("r157_cc", "r157_cc", 2.0),
    ("rss", "rss", float("inf")),
])
def test_reference_driver_equals_the_record(scenarios: list[ConcreteScenario], sut: str,
                                            field: str, critical_ttc: float) -> None:
    cs = CriticalitySettings(critical_ttc=critical_ttc)
    recs = [evaluate_criticality(s, settings=cs, wagner_scan=False).to_record()
            for s in scenarios]
    runs = simulate(make_sut(sut), CutInBatch.from_scenarios(scenarios), seeds=0)
    coll = np.array([r[f"{field}_collision"] for r in recs])
    speed = np.array([r[f"{field}_impact_speed"] for r in recs], dtype=float)
    gap = np.array([r[f"{field}_min_gap"] for r in recs], dtype=float)
    assert list(runs.collided) == list(coll)
    np.testing.assert_allclose(runs.impact_speed, speed, rtol=0, atol=TOL)
    assert list(np.isinf(runs.min_gap)) == list(np.isinf(gap))
    fin = np.isfinite(gap)
    np.testing.assert_allclose(runs.min_gap[fin], gap[fin], rtol=0, atol=TOL)
    if field != "none":
        t_b = np.array([np.nan if r[f"{field}_t_brake"] is None else r[f"{field}_t_brake"]
                        for r in recs], dtype=float)
        mine = runs.t_brake_rel_tp + CutInBatch.from_scenarios(scenarios).t_p
        # the record reports no braking when contact comes first
        shown = ~np.isnan(t_b)
        np.testing.assert_allclose(mine[shown], t_b[shown], rtol=0, atol=TOL)
    if sut == "none":
        assert coll.sum() > 50  # the sample is a critical one
    if sut == "r157_cc":
        assert coll.sum() >= 1  # the JRC-FSM gate lets some through


def test_the_jrc_rule_collides_no_less_than_the_conflict_rule(
        scenarios: list[ConcreteScenario]) -> None:
    b = CutInBatch.from_scenarios(scenarios)
    jrc = simulate(make_sut("r157_cc"), b, seeds=0)
    conflict = simulate(make_sut("r157_cc_conflict"), b, seeds=0)
    assert not np.any(conflict.collided & ~jrc.collided)


def test_drive_risk_of_none_is_the_records_risk_peak() -> None:
    """The scripted ego's r_dep peak (the record's ``risk_peak``) is the peak of the
    ``none`` SUT's own drive: the same scenes through the same engine."""
    scs = _ttc3_sample(6, 5)
    recs = [evaluate_criticality(s).to_record() for s in scs]
    runs = simulate(make_sut("none"), CutInBatch.from_scenarios(scs), seeds=0, risk=True,
                    profiles=True)
    peaks = np.array([r["risk_peak"] for r in recs], dtype=float)
    np.testing.assert_allclose(runs.r_dep_peak, peaks, rtol=0, atol=1e-9)
    assert 0.0 < peaks.min() < 1.0 == peaks.max()  # graded and saturated cases
    assert runs.profiles is not None and runs.profiles["r_dep"].shape[0] == 6
    # the profiles on demand, r_dep and r_ind at every grid step until the end: those of
    # riskcore's scenario evaluation of the scripted ego (an independent path: the
    # scene-by-scene engine over the concrete scenario)
    from riskcore.scenario_risk import evaluate_scenario

    prof = runs.profiles
    for i in (0, 3):
        ref = evaluate_scenario(scs[i])
        ok = ~np.isnan(prof["r_dep"][i])
        assert ok.sum() > 10
        for name in ("r_dep", "r_ind"):
            ref_series = np.interp(prof["t_batch"][ok], ref.t, ref.series(name))
            np.testing.assert_allclose(prof[name][i][ok], ref_series, rtol=0, atol=0.02)
        assert np.nanmax(prof["r_ind"][i]) == runs.r_ind_peak[i]
    # r_dep >= 0.5 time: whole grid steps
    steps = runs.r_dep_time_above / 0.1
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)


def test_a_careful_drive_without_contact_scores_lower_than_none() -> None:
    scs = _ttc3_sample(6, 5)
    b = CutInBatch.from_scenarios(scs)
    none = simulate(make_sut("none"), b, seeds=0, risk=True)
    careful = simulate(make_sut("r157_cc_conflict"), b, seeds=0, risk=True)
    assert np.all(careful.r_dep_peak <= none.r_dep_peak + 1e-12)
    assert np.any(careful.r_dep_peak < none.r_dep_peak)
    assert np.all(np.isnan(simulate(make_sut("none"), b, seeds=0).r_dep_peak))
