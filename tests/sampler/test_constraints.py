"""Constraints, derived quantities and the vectorised kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from datasets.cutin_model import (
    PARAM_NAMES,
    CutInParamError,
    CutInParams,
    crossing_time,
    lateral_displacement,
    speed,
)
from sampler import ConstraintError
from sampler.region.constraints import (
    PHYSICAL_BOUNDS,
    Constraint,
    Region,
    derive,
    parse_constraint,
)
from sampler.region.kinematics import crossing_kinematics
from tests.sampler.factories import base_params, synthetic_parameter_table


def _row(**kw: float) -> np.ndarray:
    p = base_params(**kw)
    return np.array([[p[k] for k in PARAM_NAMES]])


# ---------------------------------------------------------------- parsing and validation


@pytest.mark.parametrize(
    ("text", "name", "op", "value"),
    [("ttc<3", "ttc", "<", 3.0), (" v_ego >= 20 ", "v_ego", ">=", 20.0),
     ("lat_offset>-0.5", "lat_offset", ">", -0.5), ("gap<=1e2", "gap", "<=", 100.0)],
)
def test_parse_short_form(text: str, name: str, op: str, value: float) -> None:
    c = parse_constraint(text)
    assert (c.name, c.op, c.value) == (name, op, value)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [("speed<3", "valid names: p_y1"), ("ttc==3", "valid operators: < <= > >="),
     ("ttc<abc", "not a number"), ("ttc<inf", "finite"), ("ttc", "NAME OP VALUE"),
     ("__import__('os')<1", "NAME OP VALUE"), ("ttc<3;rm", "not a number")],
)
def test_parse_errors_are_clear(text: str, fragment: str) -> None:
    with pytest.raises(ConstraintError, match=fragment.replace("(", r"\(")):
        parse_constraint(text)


def test_pydantic_form_and_errors() -> None:
    c = Constraint.model_validate({"name": "ttc", "op": "<", "value": 3})
    assert c == parse_constraint("ttc<3")
    assert Constraint.model_validate_json(c.model_dump_json()) == c
    with pytest.raises(ValueError, match="valid names"):
        Constraint.model_validate({"name": "nope", "op": "<", "value": 3})
    with pytest.raises(ValueError, match="valid operators"):
        Constraint.model_validate({"name": "ttc", "op": "~", "value": 3})
    with pytest.raises(ValueError, match="extra"):
        Constraint.model_validate({"name": "ttc", "op": "<", "value": 3, "x": 1})
    with pytest.raises(ConstraintError, match="valid names"):
        Region.from_constraints([{"name": "nope", "op": "<", "value": 1}])


def test_region_json_round_trip() -> None:
    r = Region.from_constraints(["ttc<3", {"name": "v_ego", "op": ">=", "value": 20}],
                                lane_width=3.5)
    assert Region.model_validate_json(r.model_dump_json()) == r
    assert r.describe() == "ttc<3 & v_ego>=20 & physical bounds"


# ---------------------------------------------------------------- derived quantities


@pytest.mark.slow
def test_derived_by_hand() -> None:
    # no pulse: v = 25 m/s always; dv = 2 -> v_ego = 27; gap 12 -> ttc 6, thw 12/27
    d = derive(_row())
    assert d["ttc"][0] == pytest.approx(6.0)
    assert d["v_cross"][0] == pytest.approx(25.0)
    assert d["v_ego"][0] == pytest.approx(27.0)
    assert d["thw"][0] == pytest.approx(12.0 / 27.0)
    assert d["psi_max"][0] == pytest.approx(2 * 0.04 * 2.5 / math.pi)
    assert d["direction"][0] == 1.0
    assert d["v_cut_min"][0] == 25.0
    # lateral displacement against the reference integrator, lat_offset = -3.75 + disp
    p = CutInParams.from_mapping(base_params())
    disp = lateral_displacement(p)
    assert d["lat_disp"][0] == pytest.approx(disp, abs=1e-4)
    assert d["lat_offset"][0] == pytest.approx(-3.75 + disp, abs=1e-4)
    assert d["cross_margin"][0] == pytest.approx(disp - 3.75 / 2, abs=1e-4)
    assert d["end_margin"][0] == pytest.approx(3.75 / 2 - abs(-3.75 + disp), abs=1e-4)
    # moving right: starts at +3.75 and ends at 3.75 - disp
    d2 = derive(_row(p_y1=-0.04))
    assert d2["lat_offset"][0] == pytest.approx(3.75 - disp, abs=1e-4)
    assert d2["direction"][0] == -1.0


def test_ttc_infinite_when_not_closing() -> None:
    d = derive(np.vstack([_row(dv=-1.0), _row(dv=0.0)]), ["ttc"])
    assert np.isinf(d["ttc"]).all()


def test_v_cut_min_with_pulse_by_hand() -> None:
    # pulse -2 m/s^2 from t = -1 s for 3 s: speed before = 25 + 2*1 = 27, after = 27 - 6 = 21
    d = derive(_row(p_a1=-2.0, p_a2=-1.0, p_a3=3.0), ["v_cut_min"])
    assert d["v_cut_min"][0] == pytest.approx(21.0)


_finite = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    p_y1=st.floats(0.01, 0.12, **_finite), sign=st.sampled_from([-1.0, 1.0]),
    p_t=st.floats(0.8, 5.0, **_finite), p_a1=st.floats(-3.0, 3.0, **_finite),
    p_a2=st.floats(-3.0, 6.0, **_finite), p_a3=st.floats(0.0, 5.0, **_finite),
    p_v0=st.floats(15.0, 40.0, **_finite),
)
def test_vectorised_crossing_matches_reference(p_y1: float, sign: float, p_t: float,
                                               p_a1: float, p_a2: float, p_a3: float,
                                               p_v0: float) -> None:
    vec = [sign * p_y1, p_t, p_a1, p_a2, p_a3, p_v0]
    p = CutInParams(*vec, dv=0.0, gap=10.0)
    # the reference integrator needs forward motion; the bounds exclude the rest
    assume(not (speed(p, np.linspace(-5, 15, 400)) <= 1.0).any())
    kin = crossing_kinematics(np.array([vec]), 3.75 / 2)
    try:
        ref = crossing_time(p, 3.75 / 2)
    except CutInParamError:
        assert np.isnan(kin.t_cross[0])
        return
    assert kin.t_cross[0] == pytest.approx(ref, abs=2e-3)
    assert kin.v_cross[0] == pytest.approx(float(speed(p, ref)), abs=2e-3 * abs(p_a1) + 1e-9)
    assert kin.y_end[0] == pytest.approx(lateral_displacement(p), abs=1e-3)


def test_crossing_vectorised_equals_row_by_row() -> None:
    table = synthetic_parameter_table(50, seed=3)[list(PARAM_NAMES)].to_numpy()
    kin = crossing_kinematics(table, 1.875)
    for i in range(0, 50, 7):
        one = crossing_kinematics(table[i:i + 1], 1.875)
        assert one.t_cross[0] == kin.t_cross[i] and one.y_end[0] == kin.y_end[i]


def test_bad_rows_give_nan_not_errors() -> None:
    rows = np.vstack([_row(p_t=0.0), _row(p_v0=np.nan), _row(p_y1=0.001)])
    kin = crossing_kinematics(rows, 1.875)
    assert np.isnan(kin.t_cross).all()
    assert not Region().contains(rows).any()


# ---------------------------------------------------------------- regions and bounds


def test_region_contains_matches_definition() -> None:
    table = synthetic_parameter_table(400, seed=1)
    arr = table[list(PARAM_NAMES)].to_numpy()
    region = Region.from_constraints(["ttc<8", "v_ego>20", "lat_offset>-0.8"])
    d = derive(arr)
    expect = (d["ttc"] < 8) & (d["v_ego"] > 20) & (d["lat_offset"] > -0.8)
    for b in PHYSICAL_BOUNDS:
        v = arr[:, PARAM_NAMES.index(b.name)] if b.name in PARAM_NAMES else d[b.name]
        expect &= b.mask(v)
    got = region.contains(table)
    assert expect.sum() > 5
    np.testing.assert_array_equal(got, expect)


@pytest.mark.parametrize(
    ("override", "bound"),
    [({"p_v0": -1.0}, "p_v0>0"), ({"gap": -0.5}, "gap>0"), ({"p_a3": -0.1}, "p_a3>=0"),
     ({"p_a1": -5.0, "p_a2": 1.0, "p_a3": 6.0}, "v_cut_min>0"),
     ({"p_y1": 0.005}, "cross_margin>0"), ({"dv": -40.0}, "v_ego>0"),
     # ~14 m sideways at 25 m/s: runs across the ego lane into the next one
     ({"p_y1": 0.1, "p_t": 3.0}, "end_margin>0"),
     ({"p_y1": 1.2, "p_t": 2.5}, "psi_max<1.5708")],
)
def test_each_physical_bound_rejects(override: dict[str, float], bound: str) -> None:
    row = _row(**override)
    region = Region()
    assert not region.contains(row)[0]
    assert not region.in_bounds(row)[0]
    assert region.violations(row)[bound][0]
    assert Region(physical_bounds=False).contains(row)[0]


def test_params_shape_errors() -> None:
    with pytest.raises(ConstraintError, match=r"shape \(n, 8\)"):
        Region().contains(np.zeros((3, 5)))
    with pytest.raises(ConstraintError, match="missing column"):
        Region().contains({"p_y1": [0.1]})


@pytest.mark.parametrize("text", ["ttc<３", "ttc<٣", "ttc<1_000", "ttc<3.0.1", "ttc<0x10"])
def test_a_number_is_written_with_ascii_digits(text: str) -> None:
    """Issue 27 finding 5: Python's float() reads a fullwidth or Arabic-Indic digit and
    '1_000', so 'ttc<３' was accepted as 3; the grammar (and the API's pattern) refuse it."""
    with pytest.raises(ConstraintError, match=r"ASCII digits|not a number") as info:
        parse_constraint(text)
    assert info.value.problem == "not a number"


def test_the_pattern_refuses_whatever_the_parser_refuses() -> None:
    import re

    from sampler.region import constraint_pattern

    pattern = re.compile(constraint_pattern())
    accepted = ["ttc<3", " ttc <= 3 ", "btn>=1", "gap<-.5e1", "p_y1>+0.5", "v_ego>20.",
                "support==inside", "support!=extrapolated", "support<=near"]
    refused = ["ttc<３", "ttc<1_000", "ttc<inf", "foo<3", "ttc==3", "ttc", "ttc<3;x",
               "ttc<nan", "ttc<3 4"]
    for text in accepted:
        assert pattern.match(text), text
        parse_constraint(text)
    for text in refused:
        assert not pattern.match(text), text
        with pytest.raises(ConstraintError):
            parse_constraint(text)
