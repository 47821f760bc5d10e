"""Weighting g (eq. 5), the grid and weights (eq. 4), r_k (6), r_dep (8), r_ind (9), settings."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riskcore import (
    RiskSettings,
    SettingsError,
    input_grid,
    object_risk,
    risk_dependent,
    risk_independent,
    standard_grid,
    ttr_weight,
)
from tests.riskcore.reference import ref_r_dep

# g(TTR) for T_PNR = 0.5 s, T_max = 2 s: (e^{-m(TTR-0.5)} - e^{-1.5m}) / (1 - e^{-1.5m}),
# e.g. m = 1, TTR = 1: (0.606531 - 0.223130) / 0.776870 = 0.493520
HAND = [
    (1.0, 0.8, 0.6663768291380681), (1.0, 1.0, 0.493519608944346),
    (1.0, 1.5, 0.1863237232258476), (1.0, 1.9, 0.030206866825542193),
    (5.0, 0.8, 0.2227002478045707), (5.0, 1.0, 0.08157703323579671),
    (5.0, 1.9, 0.0003589961505665042), (2.0, 1.5, 0.09003057317038046),
    (0.0, 1.0, 2.0 / 3.0), (0.0, 1.25, 0.5), (0.0, 1.85, 0.1),
]


@pytest.mark.parametrize(("m", "ttr", "expected"), HAND)
def test_g_hand_values(m: float, ttr: float, expected: float) -> None:
    assert math.isclose(float(ttr_weight(ttr, 0.5, 2.0, m)), expected, rel_tol=1e-12)


@pytest.mark.parametrize("m", [0.0, 0.5, 1.0, 5.0, 1e-9, 1e3])
def test_g_ends_and_limits(m: float) -> None:
    g = ttr_weight(np.array([0.0, 0.3, 0.5, 2.0, 2.5, np.inf]), 0.5, 2.0, m)
    np.testing.assert_array_equal(g, [1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    inner = ttr_weight(np.linspace(0.5, 2.0, 31), 0.5, 2.0, m)
    assert np.all(np.diff(inner) <= 0)  # non-increasing
    assert np.all((inner >= 0) & (inner <= 1))


def test_g_for_tiny_m_tends_to_the_linear_ramp() -> None:
    ttr = np.linspace(0.5, 2.0, 7)
    np.testing.assert_allclose(ttr_weight(ttr, 0.5, 2.0, 1e-9), ttr_weight(ttr, 0.5, 2.0, 0.0),
                               atol=1e-9)


def test_g_rejects_bad_parameters() -> None:
    with pytest.raises(ValueError):
        ttr_weight(1.0, 2.0, 1.0, 1.0)
    with pytest.raises(ValueError):
        ttr_weight(1.0, 0.5, 2.0, -1.0)
    with pytest.raises(ValueError):
        ttr_weight(math.nan)


def test_standard_grid_and_weights_of_eq_4() -> None:
    z = standard_grid(10, 3.0)
    np.testing.assert_allclose(z, [-3 + 2 * i / 3 for i in range(10)], rtol=1e-15)
    np.testing.assert_array_equal(z[::-1], -z)  # exactly symmetric
    np.testing.assert_array_equal(standard_grid(1, 3.0), [0.0])
    # 2 x 2: the four corners at ±3σ weigh the same
    a, w, weight = input_grid(1.0, 0.5, -0.1, 0.02, 2, 2, 3.0)
    np.testing.assert_allclose(a, [-0.5, -0.5, 2.5, 2.5])
    np.testing.assert_allclose(w, [-0.16, -0.04, -0.16, -0.04])
    np.testing.assert_allclose(weight / weight.sum(), 0.25)
    # 3 x 3 (z = -3, 0, 3): the centre weighs 1 / (1 + 2 e^{-4.5})² = 0.9567...
    _, _, weight = input_grid(0.0, 1.0, 0.0, 1.0, 3, 3, 3.0)
    p = weight / weight.sum()
    assert math.isclose(p[4], 1 / (1 + 2 * math.exp(-4.5)) ** 2, rel_tol=1e-14)
    assert math.isclose(p[0], math.exp(-9.0) / (1 + 2 * math.exp(-4.5)) ** 2, rel_tol=1e-13)


def test_the_weights_match_normal_densities() -> None:
    from scipy.stats import norm
    a, w, weight = input_grid(0.9, 0.62, -0.09, 0.04, 10, 10, 3.0)
    dens = norm.pdf(a, 0.9, 0.62) * norm.pdf(w, -0.09, 0.04)
    np.testing.assert_allclose(weight / weight.sum(), dens / dens.sum(), rtol=1e-12)


def test_object_risk_of_all_ones_is_exactly_one() -> None:
    _, _, weight = input_grid(0.0, 1.0, 0.0, 1.0, 10, 10, 3.0)
    assert object_risk(weight, np.ones(100)) == 1.0
    assert object_risk(weight, np.zeros(100)) == 0.0
    assert math.isclose(object_risk([1.0, 3.0], [1.0, 0.2]), 0.4, rel_tol=1e-15)


@pytest.mark.slow
def test_r_dep_and_r_ind_by_hand() -> None:
    g = np.array([[0.8, 0.2], [0.6, 0.0]])
    p = np.full((2, 2), 0.5)
    # outcomes: max(.8,.6), max(.8,0), max(.2,.6), max(.2,0), each with probability 1/4
    assert math.isclose(risk_dependent(g, p), 0.6, rel_tol=1e-15)
    assert math.isclose(risk_independent([0.5, 0.3]), 0.65, rel_tol=1e-15)
    assert risk_dependent(np.zeros((0, 3)), np.zeros((0, 3))) == 0.0
    assert risk_independent([]) == 0.0
    assert risk_dependent(np.ones((3, 4)), np.full((3, 4), 0.25)) == 1.0


def _case(data: st.DataObject) -> tuple[np.ndarray, np.ndarray]:
    k = data.draw(st.integers(1, 3))
    s = data.draw(st.integers(1, 5))
    values = st.one_of(st.sampled_from([0.0, 1.0, 0.5, 0.25]), st.floats(0.0, 1.0))
    g = np.array([[data.draw(values) for _ in range(s)] for _ in range(k)])
    raw = np.array([[data.draw(st.floats(0.01, 1.0)) for _ in range(s)] for _ in range(k)])
    return g, raw / raw.sum(axis=1, keepdims=True)


@settings(max_examples=150, deadline=None)
@given(st.data())
@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_r_dep_equals_brute_force_enumeration(data: st.DataObject) -> None:
    g, p = _case(data)
    expected = ref_r_dep(list(g), list(p))
    assert math.isclose(risk_dependent(g, p), expected, rel_tol=1e-12, abs_tol=1e-15)


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_r_dep_never_exceeds_r_ind(data: st.DataObject) -> None:
    g, p = _case(data)
    r_k = [object_risk(p[k], g[k]) for k in range(g.shape[0])]
    r_dep = risk_dependent(g, p)
    assert r_dep <= risk_independent(r_k) + 1e-12
    assert max(r_k) <= r_dep + 1e-12  # and never below the largest single-object risk


def test_r_dep_enumeration_with_the_papers_shapes() -> None:
    """Three objects with 10 samples each: 1000 outcomes enumerated literally."""
    rng = np.random.default_rng(3)
    g = np.where(rng.random((3, 10)) < 0.4, 0.0, rng.choice([1.0, 0.3, 0.7], (3, 10)))
    p = rng.dirichlet(np.ones(10), size=3)
    total = 0.0
    for combo in itertools.product(range(10), repeat=3):
        total += math.prod(p[k, i] for k, i in enumerate(combo)) * max(
            g[k, i] for k, i in enumerate(combo))
    assert math.isclose(risk_dependent(g, p), total, rel_tol=1e-12)


def test_r_dep_validates_its_input() -> None:
    with pytest.raises(ValueError, match="same shape"):
        risk_dependent(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match=">= 0"):
        risk_dependent(-np.ones((1, 2)), np.full((1, 2), 0.5))


# --- settings ------------------------------------------------------------------------


def test_table_ii_defaults() -> None:
    s = RiskSettings()
    assert (s.horizon, s.dt, s.n_a, s.n_omega, s.t_pnr, s.t_max, s.m) == (
        3.0, 0.1, 10, 10, 0.5, 2.0, 1.0)
    assert s.n_steps == 30 and s.n_samples == 100
    assert RiskSettings.from_dict(s.to_dict()) == s


@pytest.mark.parametrize(("changes", "field"), [
    ({"t_pnr": 2.0}, "t_pnr"), ({"horizon": 0.25}, "horizon"), ({"n_a": 0}, "n_a"),
    ({"n_omega": 2.5}, "n_omega"), ({"brake_max": -1.0}, "brake_max"),
    ({"dt": math.nan}, "dt"), ({"m": -0.5}, "m"), ({"n_a": True}, "n_a"),
    ({"lat_accel_max": "6"}, "lat_accel_max"), ({"speed": 3.0}, "unknown setting"),
    ({"dt": 0.001}, "at most 1000 steps"),
])
def test_bad_settings_name_the_field(changes: dict[str, object], field: str) -> None:
    with pytest.raises(SettingsError, match=field):
        RiskSettings().replace(**changes)
