"""Criticality from parameter vectors equals the record of the built scenario; constraints."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from datasets.cutin_model import PARAM_NAMES
from riskcore.criticality import CriticalitySettings, evaluate_criticality
from sampler import (
    BuilderError,
    CutInGMM,
    PRegionEstimator,
    Region,
    build_scenario,
    parse_constraint,
    sample,
)
from sampler.region.criticality import CRITICALITY_QUANTITIES, criticality_quantities
from tests.riskcore.driver_reference import (
    IMPACT_TOL,
    clear_outcome,
    generated_cut_ins,
    reference_drive,
)
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


# --------------------------------------------------------------------------- fast path
_QUANTITIES = ("t_p", "a_req", "btn", "r157_collision", "r157_impact_speed",
               "none_collision")


def _assert_same(fast: dict[str, np.ndarray], grid: dict[str, np.ndarray]) -> None:
    """The pruned kernels check the same grid points as the grid path: equal results up
    to floating-point rounding (the contact time is a root found to ~1e-15 s)."""
    for name in _QUANTITIES:
        a, b = fast[name], grid[name]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
        np.testing.assert_array_equal(np.isinf(a), np.isinf(b), err_msg=name)
        ok = np.isfinite(a) & np.isfinite(b)
        np.testing.assert_allclose(a[ok], b[ok], rtol=1e-9, atol=1e-9, err_msg=name)


@pytest.mark.parametrize("critical_ttc", [math.inf, 2.0])
def test_fast_path_equals_the_grid_path(critical_ttc: float) -> None:
    rows = _closing_rows(400, seed=11)
    # a quick cut-in close ahead and much slower: contact before braking can start
    rows[:40, 0] = np.where(rows[:40, 0] > 0, 0.25, -0.25)
    rows[:40, 1] = 1.5
    rows[:40, 6] = 22.0
    rows[:40, 7] = np.linspace(0.5, 8.0, 40)
    s = CriticalitySettings(critical_ttc=critical_ttc)
    fast = criticality_quantities(rows, settings=s, with_ttr=False)
    grid = criticality_quantities(rows, settings=s, with_ttr=False, baseline=True)
    _assert_same(fast, grid)
    # the comparison covers every outcome the drivers can have
    assert np.nansum(fast["none_collision"]) >= 100
    assert np.nansum(fast["r157_collision"]) >= 5
    assert np.nansum(fast["none_collision"] == 0) >= 20
    assert np.isinf(fast["a_req"]).sum() >= 1


@settings(max_examples=60, deadline=None)
@given(p_y1=st.floats(0.01, 0.12), side=st.sampled_from([-1.0, 1.0]),
       p_t=st.floats(1.0, 4.0), p_a1=st.floats(-3.0, 1.5), p_a2=st.floats(-1.0, 4.0),
       p_a3=st.floats(0.0, 4.0), p_v0=st.floats(8.0, 40.0), dv=st.floats(-4.0, 20.0),
       gap=st.floats(0.5, 60.0), critical_ttc=st.sampled_from([math.inf, 2.0, 0.5]))
def test_fast_path_equals_the_grid_path_on_random_rows(
        p_y1: float, side: float, p_t: float, p_a1: float, p_a2: float, p_a3: float,
        p_v0: float, dv: float, gap: float, critical_ttc: float) -> None:
    row = np.array([[side * p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap]])
    s = CriticalitySettings(critical_ttc=critical_ttc)
    _assert_same(criticality_quantities(row, settings=s, with_ttr=False),
                 criticality_quantities(row, settings=s, with_ttr=False, baseline=True))


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(params=generated_cut_ins())
def test_fast_path_agrees_with_the_slow_reference(params: dict[str, float]) -> None:
    # the R157 and constant-speed drivers of the fast path against the plain 1 ms loop on
    # the built scenario, collision for collision
    try:
        scen = build_scenario(params)
    except BuilderError:
        assume(False)
        return
    rec = evaluate_criticality(scen).to_record()
    assume(clear_outcome(rec, "none") and clear_outcome(rec, "r157_cc"))
    q = criticality_quantities(np.array([[params[n] for n in PARAM_NAMES]]), with_ttr=False)
    s = CriticalitySettings()
    for driver, key in (("r157", "r157_collision"), ("none", "none_collision")):
        ref_hit, ref_speed = reference_drive(scen, driver, s)
        assert bool(q[key][0]) is ref_hit, (driver, rec)
        if driver == "r157" and ref_hit:
            assert q["r157_impact_speed"][0] == pytest.approx(ref_speed, abs=IMPACT_TOL)


def test_step_must_divide_the_sample_step() -> None:
    with pytest.raises(ValueError, match=r"settings\.step"):
        criticality_quantities(_closing_rows(2, seed=1),
                               settings=CriticalitySettings(step=0.03))


def test_constraints_on_btn_and_ttr_true_together() -> None:
    # btn is evaluated without the TTR scan; ttr_true asked for afterwards still gets it
    rows = _closing_rows(200, seed=6)
    q = criticality_quantities(rows)
    bounds = Region.from_constraints([]).contains(rows)
    for cons in (["btn>0.1", "ttr_true<4"], ["ttr_true<4", "btn>0.1"]):
        inside = Region.from_constraints(cons).contains(rows)
        expect = bounds & (q["btn"] > 0.1) & (q["ttr_true"] < 4)
        np.testing.assert_array_equal(inside, expect)
        assert 5 <= inside.sum() < bounds.sum()


def test_a_pulse_that_outlasts_the_scripted_contact_is_in_the_scenario() -> None:
    # the cutter brakes (-0.743 m/s^2) from 5.9 s to 16.6 s after the lead-in, long after
    # the scripted ego hits it (8.5 s): the careful driver, braking from t_p + 0.75 s,
    # meets the still-braking cutter, so the scenario must run until the pulse is over
    # (19.07 s) or a_req comes from a cut-off (0.57 m/s^2 with the cutter's speed held
    # from 11.5 s on, instead of 0.69)
    row = [0.023, 3.557, -0.743, 5.926, 10.641, 22.37, 2.458, 6.714]
    scen = build_scenario(dict(zip(PARAM_NAMES, row, strict=True)), lane_width=3.5)
    assert scen.provenance["resolution"] == "contact"
    assert scen.provenance["t_resolved"] < 9.0 < 2.5 + 5.926 + 10.641 <= scen.t[-1]
    rec = evaluate_criticality(scen).to_record()
    q = criticality_quantities(np.array([row]), 3.5, with_ttr=False)
    assert rec["a_req"] == pytest.approx(q["a_req"][0], rel=1e-5)
    assert rec["a_req"] > 0.68  # type: ignore[operator]
    assert q["r157_collision"][0] == float(bool(rec["r157_cc_collision"]))


def test_a_manoeuvre_longer_than_a_scenario_may_be_is_not_a_cut_in() -> None:
    # a 24,000 s acceleration pulse: the builder refuses it (at most 3600 s), the sampler
    # level gives NaN without allocating its samples
    row = [0.273, 0.841, 0.542, -7.95, 24048.7, 23.0, 11.7, 29.3]
    with pytest.raises(BuilderError, match="at most"):
        build_scenario(dict(zip(PARAM_NAMES, row, strict=True)))
    q = criticality_quantities(np.array([row, [0.273, 0.841, 0.0, 0.0, 1e300, 23.0, 11.7,
                                                 29.3]]))
    for name in CRITICALITY_QUANTITIES:
        assert np.isnan(q[name]).all(), name
