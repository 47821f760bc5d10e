"""The least-squares fits: hand-computed cases, a slow reference, property tests."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets.cutin_model import CutInParams, lateral_displacement, motion
from datasets.errors import ExtractionError
from datasets.extract_rows import _crossing_time
from datasets.fit import _ramp_grid, fit_lateral, fit_pulse, lateral_model, max_lateral_speed


def _params(**kw: float) -> CutInParams:
    base = dict(p_y1=0.03, p_t=2.0, p_a1=0.0, p_a2=0.0, p_a3=0.0, p_v0=25.0, dv=0.0, gap=10.0)
    base.update(kw)
    return CutInParams(**base)


def test_lateral_model_matches_cutin_model_motion() -> None:
    # independent reference: cutin_model integrates on a 1 ms grid
    p = _params(p_y1=0.04, p_t=2.5, p_a1=0.8, p_a2=0.5, p_a3=1.5)
    t = np.arange(-2.0, 8.0, 0.04)
    m = motion(p, t)
    y = lateral_model(t, m.v, p.p_y1, p.p_t, 0.0, 0.0)
    assert np.max(np.abs(y - m.y)) < 2e-3


def test_lateral_model_small_angle_by_hand() -> None:
    # constant v, tiny angle: y(2 p_t) = 2 v p_y1 p_t^2 / pi = 2*20*0.001*4/pi = 0.050930 m
    t = np.linspace(0.0, 4.0, 4001)
    y = lateral_model(t, np.full_like(t, 20.0), 0.001, 2.0, 0.0, 1.0)
    assert y[-1] - 1.0 == pytest.approx(0.16 / np.pi, rel=1e-5)
    assert y[0] == 1.0


def test_lateral_model_start_before_data() -> None:
    # the part before t[0] is integrated with v[0]: same result as data starting earlier
    t = np.arange(-1.0, 6.0, 0.05)
    v = np.full_like(t, 22.0)
    full = lateral_model(t, v, 0.03, 2.0, 0.0, -3.5)
    late = lateral_model(t[30:], v[30:], 0.03, 2.0, 0.0, -3.5)
    assert np.max(np.abs(full[30:] - late)) < 1e-3


def test_fit_lateral_recovers_exact_model_data() -> None:
    p = _params(p_y1=-0.035, p_t=2.2, p_v0=30.0)
    t = np.arange(-3.0, 7.5, 0.04)
    m = motion(p, t)
    fit = fit_lateral(t + 100.0, m.y + 1.7, m.v)
    assert fit.p_y1 == pytest.approx(p.p_y1, rel=5e-3)
    assert fit.p_t == pytest.approx(p.p_t, rel=5e-3)
    assert fit.t0 == pytest.approx(100.0, abs=0.01)
    assert fit.y_start == pytest.approx(1.7, abs=5e-3)
    assert fit.displacement == pytest.approx(lateral_displacement(p), abs=5e-3)
    assert fit.rms < 5e-3


def test_fit_lateral_rejects_no_motion() -> None:
    t = np.arange(0.0, 5.0, 0.1)
    with pytest.raises(ExtractionError, match="displacement"):
        fit_lateral(t, np.full_like(t, 0.2), np.full_like(t, 20.0))
    with pytest.raises(ExtractionError, match="at least 8"):
        fit_lateral(t[:5], t[:5], t[:5])


@settings(max_examples=15, deadline=None)
@given(
    disp=st.floats(2.8, 4.2), p_t=st.floats(1.0, 3.5), v=st.floats(12.0, 38.0),
    left=st.booleans(), noise_seed=st.integers(0, 2**16),
)
def test_fit_lateral_property_recovers_p_t_and_p_y1(
    disp: float, p_t: float, v: float, left: bool, noise_seed: int
) -> None:
    sign = 1.0 if left else -1.0
    p_y1 = sign * disp * np.pi / (2.0 * v * p_t**2)
    p = _params(p_y1=p_y1, p_t=p_t, p_v0=v)
    t = np.arange(-2.5, 2.0 * p_t + 2.5, 0.04)
    m = motion(p, t)
    rng = np.random.default_rng(noise_seed)
    y = np.round(m.y + rng.normal(0.0, 0.01, t.size), 2)  # highD-like rounding and noise
    fit = fit_lateral(t, y, m.v)
    assert np.sign(fit.p_y1) == sign
    assert fit.p_t == pytest.approx(p_t, rel=0.03)
    assert fit.p_y1 == pytest.approx(p_y1, rel=0.05)
    assert fit.t0 == pytest.approx(0.0, abs=0.1)


def test_fit_pulse_hand_ramp() -> None:
    # 20 m/s until t = 1, +1 m/s^2 until t = 3, then 22 m/s; lateral start t0 = 0.5
    t = np.arange(0.0, 6.0, 0.04)
    v = 20.0 + np.clip(t - 1.0, 0.0, 2.0)
    fit = fit_pulse(t, v, t0=0.5)
    assert fit.p_a1 == pytest.approx(1.0, abs=1e-3)
    assert fit.p_a2 == pytest.approx(0.5, abs=0.01)
    assert fit.p_a3 == pytest.approx(2.0, abs=0.01)
    assert fit.p_v0 == pytest.approx(20.0, abs=1e-3)
    assert fit.rms < 1e-3


def test_fit_pulse_constant_speed_is_no_pulse() -> None:
    t = np.arange(0.0, 6.0, 0.04)
    fit = fit_pulse(t, np.full_like(t, 27.0), t0=2.0)
    assert (fit.p_a1, fit.p_a2, fit.p_a3) == (0.0, 0.0, 0.0)
    assert fit.p_v0 == 27.0


def _ramp_reference(t: np.ndarray, v: np.ndarray, step: float, min_dur: float) -> float:
    """Slow reference: every (tau1, tau2) pair solved with lstsq; returns the best RSS."""
    cand = np.arange(t[0], t[-1] + 1e-9, step)
    best = np.inf
    for a, b in itertools.combinations(cand, 2):
        if b - a < min_dur - 1e-12:
            continue
        r = np.clip((t - a) / (b - a), 0.0, 1.0)
        basis = np.stack([1.0 - r, r], axis=1)
        coef, *_ = np.linalg.lstsq(basis, v, rcond=None)
        best = min(best, float(np.sum((basis @ coef - v) ** 2)))
    return best


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ramp_grid_matches_slow_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 4.0, 0.1)
    v = 20.0 + np.clip(t - rng.uniform(0.5, 1.5), 0.0, rng.uniform(0.5, 2.0)) \
        + rng.normal(0.0, 0.05, t.size)
    a, b, v1, v2 = _ramp_grid(t, v, 0.2, 0.2)
    r = np.clip((t - a) / (b - a), 0.0, 1.0)
    rss = float(np.sum((v1 + (v2 - v1) * r - v) ** 2))
    assert rss == pytest.approx(_ramp_reference(t, v, 0.2, 0.2), rel=1e-9, abs=1e-12)


def test_crossing_time_by_hand() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([-3.5, -3.0, -1.0, 0.0])
    # marking at -1.75 moving left: between t=1 (-3.0) and t=2 (-1.0): 1 + 1.25/2 = 1.625
    assert _crossing_time(t, y, -1.75, 1.0) == pytest.approx(1.625)
    # never crossing to the right
    assert np.isnan(_crossing_time(t, y, -4.0, -1.0))
    # already beyond the marking at the start: a crossing needs the start side first
    assert np.isnan(_crossing_time(t, y, -5.0, 1.0))


def test_max_lateral_speed_by_hand() -> None:
    t = np.arange(0.0, 2.0, 0.04)
    assert max_lateral_speed(t, 0.8 * t) == pytest.approx(0.8)
