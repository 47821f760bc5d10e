"""Data support (sampler.model.support): per-parameter excess, nearest real cut-in, class;
persistence; the constraints on it; the limit state's margin."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets import PARAM_NAMES
from sampler import ConstraintError, CutInGMM, ModelError, Region, parse_constraint
from sampler.methods.subset import region_limit_state
from sampler.model.support import attach_support, training_support
from tests.sampler.factories import base_params, synthetic_parameter_table

# a two-feature model whose support can be computed by hand: gap (log) and dv (identity)
GAPS = [10.0, 12.0, 15.0, 18.0, 20.0, 22.0, 25.0, 30.0, 35.0, 40.0, 8.0, 28.0]
DVS = [1.0, -2.0, 0.5, -1.0, 2.0, -3.0, 0.0, 1.5, -0.5, 2.5, -1.5, 3.0]


def _hand_table() -> pd.DataFrame:
    rows = []
    for g, d in zip(GAPS, DVS, strict=True):
        rows.append({**base_params(), "gap": g, "dv": d})
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def hand_model() -> CutInGMM:
    return CutInGMM(features=("gap", "dv"), k_range=(1, 1), n_init=1).fit(_hand_table())


@pytest.fixture(scope="module")
def synth_model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1).fit(synthetic_parameter_table(300, seed=4))


def _hand_z(gap: float, dv: float) -> tuple[float, float]:
    lg = np.log(np.array(GAPS))
    d = np.array(DVS)
    return ((math.log(gap) - lg.mean()) / lg.std(), (dv - d.mean()) / d.std())


def test_hand_computed_support(hand_model: CutInGMM) -> None:
    zs = [_hand_z(g, d) for g, d in zip(GAPS, DVS, strict=True)]
    loo = []
    for i, (a, b) in enumerate(zs):
        loo.append(min(math.hypot(a - c, b - e) for j, (c, e) in enumerate(zs) if j != i))
    ts = training_support(hand_model)
    assert ts.loo.tolist() == pytest.approx(loo, abs=1e-12)
    assert ts.d_inside == pytest.approx(float(np.quantile(loo, 0.95)), abs=1e-12)
    assert ts.d_near == pytest.approx(float(np.quantile(loo, 0.99)), abs=1e-12)
    sd_gap, sd_dv = np.std(GAPS, ddof=1), np.std(DVS, ddof=1)
    # a vector above both ranges: gap 50 m (max 40), dv 4 m/s (max 3)
    x = np.array([[*[base_params()[k] for k in PARAM_NAMES[:6]], 4.0, 50.0]])
    sm = hand_model.support_measures(x)
    rec = sm.record(0)
    by_name = {o["name"]: o for o in rec["support_outside"]}
    assert by_name["gap"]["excess"] == pytest.approx(10.0)
    assert by_name["gap"]["excess_sd"] == pytest.approx(10.0 / sd_gap)
    assert by_name["dv"]["excess"] == pytest.approx(1.0)
    assert by_name["dv"]["excess_sd"] == pytest.approx(1.0 / sd_dv)
    assert by_name["gap"]["unit"] == "m" and by_name["dv"]["unit"] == "m/s"
    z = _hand_z(50.0, 4.0)
    nearest = min(math.hypot(z[0] - a, z[1] - b) for a, b in zs)
    assert rec["support_distance"] == pytest.approx(nearest, abs=1e-12)
    assert rec["support_excess"] == pytest.approx(max(10.0 / sd_gap, 1.0 / sd_dv))
    assert rec["support"] == "extrapolated"  # 10 m is more than 0.5 sd beyond the range
    # below the range: gap 7 m (min 8) -> negative excess
    x2 = x.copy()
    x2[0, 6], x2[0, 7] = 0.0, 7.0
    out = hand_model.support_measures(x2).record(0)["support_outside"]
    assert [o["name"] for o in out] == ["gap"]
    assert out[0]["excess"] == pytest.approx(-1.0)


def test_training_rows_are_inside(hand_model: CutInGMM) -> None:
    x = hand_model.params_matrix(np.column_stack([GAPS, DVS]))
    sm = hand_model.support_measures(x)
    assert (sm.distance == 0.0).all()
    assert (sm.largest == 0.0).all()
    assert sm.classes() == ["inside"] * len(GAPS)
    assert sm.shares() == {"inside": len(GAPS), "near": 0, "extrapolated": 0}


def _slow_support(model: CutInGMM, x: np.ndarray) -> tuple[list[float], list[float], list[int]]:
    """Straight loops: the reference the vectorised measures must match."""
    data = np.asarray(model.support_["points"])
    lo, hi, sd = data.min(0), data.max(0), data.std(0, ddof=1)
    cols = [PARAM_NAMES.index(f) for f in model.features_]
    zd = model.to_z(data)
    loo = []
    for i in range(len(zd)):
        loo.append(min(float(np.sqrt(((zd[i] - zd[j]) ** 2).sum()))
                       for j in range(len(zd)) if j != i))
    d_in, d_near = np.quantile(loo, 0.95), np.quantile(loo, 0.99)
    dist, largest, codes = [], [], []
    for row in x:
        v = row[cols]
        worst = 0.0
        for j in range(len(cols)):
            e = v[j] - hi[j] if v[j] > hi[j] else (v[j] - lo[j] if v[j] < lo[j] else 0.0)
            worst = max(worst, abs(e) / sd[j])
        z = model.to_z(v[None, :])[0]
        d = min(float(np.sqrt(((z - p) ** 2).sum())) for p in zd)
        dist.append(d)
        largest.append(worst)
        codes.append(0 if worst == 0 and d <= d_in else 1 if worst <= 0.5 and d <= d_near
                     else 2)
    return dist, largest, codes


@pytest.mark.slow
def test_vectorised_equals_slow_reference(synth_model: CutInGMM) -> None:
    rng = np.random.default_rng(3)
    z = synth_model.sample_z(300, rng, scale=1.6)  # wide draws: all three classes
    x = synth_model.params_matrix(synth_model.from_z(z))
    sm = synth_model.support_measures(x)
    dist, largest, codes = _slow_support(synth_model, x)
    np.testing.assert_allclose(sm.distance, dist, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sm.largest, largest, rtol=1e-12, atol=1e-12)
    assert sm.code.astype(int).tolist() == codes
    assert set(codes) == {0, 1, 2}


@settings(max_examples=60, deadline=None)
@given(row=st.integers(0, 299), j=st.integers(0, 7),
       steps=st.lists(st.floats(0.0, 5.0), min_size=2, max_size=6))
def test_moving_out_of_range_never_improves_support(synth_model: CutInGMM, row: int, j: int,
                                                    steps: list[float]) -> None:
    """Pushing one parameter further beyond the data's largest value: the excess grows
    with it, the class code never falls."""
    data = np.asarray(synth_model.support_["points"])
    base = synth_model.params_matrix(data[row:row + 1])
    hi, sd = data[:, j].max(), data[:, j].std(ddof=1)
    xs = np.repeat(base, len(steps), axis=0)
    offsets = np.sort(np.asarray(steps))
    xs[:, j] = hi + offsets * sd
    sm = synth_model.support_measures(xs)
    assert np.all(np.diff(sm.excess_sd[:, j]) >= -1e-12)
    np.testing.assert_allclose(sm.excess_sd[:, j], offsets, atol=1e-9)
    assert np.all(sm.code[offsets > 0.5] == 2)


def test_json_round_trip_keeps_support(synth_model: CutInGMM) -> None:
    loaded = CutInGMM.from_json(synth_model.to_json())
    x = synth_model.params_matrix(synth_model.sample(200, np.random.default_rng(1)))
    a, b = synth_model.support_measures(x), loaded.support_measures(x)
    np.testing.assert_array_equal(a.distance, b.distance)
    np.testing.assert_array_equal(a.code, b.code)


def test_old_model_files_load_and_get_support_attached() -> None:
    table = synthetic_parameter_table(120, seed=9)
    model = CutInGMM(k_range=(1, 1), n_init=1).fit(table)
    data = json.loads(model.to_json())
    del data["support"]  # as written before data support
    old = CutInGMM.from_dict(data)
    x = model.params_matrix(model.sample(5, np.random.default_rng(0)))
    np.testing.assert_array_equal(old.log_density(x[:, :8]), model.log_density(x[:, :8]))
    with pytest.raises(ModelError, match="no training rows"):
        old.support_measures(x)
    with pytest.raises(ModelError, match="not the model's training data"):
        attach_support(old, synthetic_parameter_table(120, seed=10))
    attach_support(old, table)
    np.testing.assert_array_equal(old.support_measures(x).distance,
                                  model.support_measures(x).distance)


def test_tampered_support_points_are_refused(synth_model: CutInGMM) -> None:
    data = json.loads(synth_model.to_json())
    data["support"]["points"][0][0] += 0.001
    with pytest.raises(ModelError, match=r"support\.points: not the training data"):
        CutInGMM.from_dict(data)
    data = json.loads(synth_model.to_json())
    data["support"]["rule"]["near_excess_sd"] = -1
    with pytest.raises(ModelError, match=r"support\.rule\.near_excess_sd"):
        CutInGMM.from_dict(data)


@pytest.mark.parametrize(("text", "op", "value", "shown"), [
    ("support!=extrapolated", "<=", 1.0, "support!=extrapolated"),
    ("support==inside", "<=", 0.0, "support==inside"),
    ("support = inside", "<=", 0.0, "support==inside"),
    ("support<=near", "<=", 1.0, "support!=extrapolated"),
    ("support>=near", ">=", 1.0, "support!=inside"),
    ("support==extrapolated", ">=", 2.0, "support==extrapolated"),
    ("support!=inside", ">=", 1.0, "support!=inside"),
    ("support<extrapolated", "<=", 1.0, "support!=extrapolated"),
    ("support<2", "<=", 1.0, "support!=extrapolated"),
    ("support>inside", ">=", 1.0, "support!=inside"),
])
def test_support_constraint_words(text: str, op: str, value: float, shown: str) -> None:
    c = parse_constraint(text)
    assert (c.name, c.op, c.value) == ("support", op, value)
    assert str(c) == shown
    assert parse_constraint(str(c)) == c


def test_support_constraint_in_json() -> None:
    region = Region.from_constraints([{"name": "support", "op": "!=",
                                       "value": "extrapolated"}])
    assert (region.constraints[0].op, region.constraints[0].value) == ("<=", 1.0)
    assert region.constraints[0] == parse_constraint("support<2")


@pytest.mark.parametrize(("text", "needle"), [
    ("support==near", "two constraints"),
    ("support!=near", "two constraints"),
    ("support!=elsewhere", "one of inside, near, extrapolated"),
    ("support<5", "one of inside"),
    ("support<1.5", "one of inside"),
])
def test_bad_support_constraints(text: str, needle: str) -> None:
    with pytest.raises(ConstraintError, match=needle):
        parse_constraint(text)


@pytest.mark.parametrize(("text", "hint"), [("tcc<3", "'ttc'"), ("TTC<3", "'ttc'"),
                                            ("btnn>0.5", "'btn'"), ("suport<1", "'support'")])
def test_unknown_quantity_says_did_you_mean(text: str, hint: str) -> None:
    with pytest.raises(ConstraintError, match=f"did you mean {hint}"):
        parse_constraint(text)


@pytest.mark.parametrize("constraints", [
    ["support!=extrapolated"], ["support==inside"], ["support!=inside"],
    ["support==extrapolated"], ["support_distance<2"], ["support_excess<=0.2"],
    ["gap<15", "support!=extrapolated"],
])
def test_region_and_limit_state_agree_on_support(synth_model: CutInGMM,
                                                 constraints: list[str]) -> None:
    region = Region.from_constraints(constraints, lane_width=synth_model.lane_width_)
    bound = region.bind(synth_model)
    rng = np.random.default_rng(5)
    z = synth_model.sample_z(3000, rng, scale=1.4)
    x = synth_model.params_matrix(synth_model.from_z(z))
    inside = bound.contains(x)
    sm = synth_model.support_measures(x)
    in_bounds = bound.in_bounds(x)
    for c in region.constraints:  # the region's own reading of the class codes
        if c.name == "support":
            expect = {"<": np.less, "<=": np.less_equal, ">": np.greater,
                      ">=": np.greater_equal}[c.op](sm.code, c.value)
            assert np.array_equal(inside & ~expect, np.zeros_like(inside))
    g = region_limit_state(synth_model, region, np.random.default_rng(0))(z)
    assert np.array_equal(g <= 0, inside)
    assert inside.any() and (~inside & in_bounds).any()
    # the limit state is not flat on the rows outside (subset levels can progress)
    outside = g[np.isfinite(g) & (g > 0)]
    assert np.unique(outside).size > 0.9 * outside.size


def test_support_quantities_need_the_model() -> None:
    with pytest.raises(ConstraintError, match="support needs the model"):
        Region.from_constraints(["support!=extrapolated"]).contains(
            np.array([[base_params()[k] for k in PARAM_NAMES]]))
