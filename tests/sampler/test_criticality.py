"""Criticality from parameter vectors equals the record of the built scenario; constraints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from datasets.cutin_model import PARAM_NAMES
from riskcore.criticality import evaluate_criticality
from sampler import (
    BuilderError,
    CutInGMM,
    PRegionEstimator,
    Region,
    build_scenario,
    parse_constraint,
    sample,
)
from sampler.criticality import CRITICALITY_QUANTITIES, criticality_quantities
from tests.sampler.factories import synthetic_parameter_table

_MAP = {"t_p": "t_p", "a_req": "a_req", "btn": "btn", "ttr_true": "ttr_true",
        "r157_collision": "r157_cc_collision", "r157_impact_speed": "r157_cc_impact_speed",
        "none_collision": "none_collision"}


def _closing_rows(n: int, seed: int) -> np.ndarray:
    """Plausible cut-ins, most of them closing (so the drivers have work to do)."""
    table = synthetic_parameter_table(n=n, seed=seed)
    rng = np.random.default_rng(seed)
    table["dv"] = rng.uniform(-1.0, 12.0, n)
    table["gap"] = rng.uniform(1.0, 30.0, n)
    return table[list(PARAM_NAMES)].to_numpy(float)


def test_vector_quantities_equal_the_scenario_record() -> None:
    rows = _closing_rows(40, seed=3)
    q = criticality_quantities(rows)
    checked = 0
    for i, row in enumerate(rows):
        try:
            scen = build_scenario(dict(zip(PARAM_NAMES, row, strict=True)))
        except BuilderError:
            assert all(math.isnan(q[name][i]) for name in q)
            continue
        rec = evaluate_criticality(scen).to_record()
        checked += 1
        assert q["t_p"][i] == pytest.approx(rec["t_p"], abs=1e-4)
        assert q["none_collision"][i] == float(bool(rec["none_collision"]))
        # a contact within millimetres of a miss may go either way between the two
        near = (rec["r157_cc_collision"] and rec["r157_cc_impact_speed"] < 0.05) or (
            not rec["r157_cc_collision"] and rec["r157_cc_min_gap"] < 0.01)
        if not near:
            assert q["r157_collision"][i] == float(bool(rec["r157_cc_collision"])), i
            assert q["r157_impact_speed"][i] == pytest.approx(
                rec["r157_cc_impact_speed"], abs=2e-3)
        assert q["a_req"][i] == pytest.approx(rec["a_req"], rel=1e-3, abs=1e-3)
        assert q["btn"][i] == pytest.approx(rec["btn"], rel=1e-3, abs=1e-4)
        # TTR is on riskcore's 0.1 s steps: equal, or one step off at a boundary
        ttr_s = rec["ttr_true"]
        assert isinstance(ttr_s, float)
        if math.isinf(ttr_s):
            assert math.isinf(q["ttr_true"][i])
        else:
            assert abs(q["ttr_true"][i] - ttr_s) <= 0.1 + 1e-9
    assert checked >= 30
    assert sum(q["none_collision"][np.isfinite(q["none_collision"])]) >= 10


def test_rows_that_are_not_cut_ins_give_nan() -> None:
    rows = np.array([[0.0, 2.0, 0, 0, 0, 25, 3, 10],      # no lateral motion
                     [0.002, 2.0, 0, 0, 0, 25, 3, 10],    # never crosses
                     [0.05, 2.0, 0, 0, 0, 25, -40, 10],   # ego speed < 0
                     [0.05, -1.0, 0, 0, 0, 25, 3, 10]])   # p_t < 0
    q = criticality_quantities(rows)
    for name in CRITICALITY_QUANTITIES:
        assert np.isnan(q[name]).all(), name


def test_criticality_constraints_are_evaluated_last() -> None:
    c = parse_constraint("btn>0.7")
    assert c.tier == 2 and parse_constraint("t_cross<3").tier == 1
    assert parse_constraint("ttc<3").tier == 0
    rows = _closing_rows(200, seed=5)
    region = Region.from_constraints(["ttc<3", "btn>0.2", "btn<1"])
    inside = region.contains(rows)
    q = criticality_quantities(rows)
    ttc = np.where(rows[:, 6] > 0, rows[:, 7] / np.where(rows[:, 6] > 0, rows[:, 6], 1), np.inf)
    bounds = Region.from_constraints([]).contains(rows)
    expect = bounds & (ttc < 3) & (q["btn"] > 0.2) & (q["btn"] < 1)
    np.testing.assert_array_equal(inside, expect)
    assert inside.sum() >= 5


@pytest.mark.slow
def test_sampling_critical_but_preventable() -> None:
    model = CutInGMM(random_state=0).fit(synthetic_parameter_table(400, seed=1))
    light = PRegionEstimator(pilot_hits=30, n_is=1 << 12, n_bounds=1 << 12,
                             search_draws=1 << 14)
    ss = sample(model, ["ttc<3", "btn>0.2", "btn<1"], n=8, seed=2, estimator=light)
    lw = float(ss.region.lane_width)
    params = np.asarray(ss.params[list(PARAM_NAMES)] if hasattr(ss.params, "columns")
                        else ss.params, dtype=float)
    for row in params:
        rec = evaluate_criticality(build_scenario(dict(zip(PARAM_NAMES, row, strict=True)),
                                                  lane_width=lw)).to_record()
        assert 0.2 - 1e-3 < rec["btn"] < 1.0 + 1e-3  # type: ignore[operator]
