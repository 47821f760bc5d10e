"""The batched Wagner scan (``_Wagner.first_reaching``, one compiled call per block of
steps) against one ``scene()`` call per step, the straightforward path."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riskcore.criticality import CriticalitySettings
from riskcore.criticality.drivers import _frames
from riskcore.criticality.wagner import _Wagner
from riskcore.scene import default_surfaces
from riskcore.settings import RiskSettings
from sampler.scenario.builder import build_scenario
from tests.sampler.factories import base_params


def _wagner(**overrides: float) -> _Wagner:
    sc = build_scenario(base_params(**overrides))
    s = CriticalitySettings()
    f = _frames(sc.t, sc.ego, sc.objects[0], s)
    return _Wagner(sc, f, RiskSettings(), default_surfaces(), s)


def _reference(w: _Wagner) -> list[float]:
    return [w.scene(float(tk))[0] for tk in w.t]


@pytest.mark.parametrize("overrides", [{}, {"gap": 4.0, "dv": 6.0}, {"dv": -1.0},
                                       {"p_y1": -0.05, "gap": 8.0, "dv": 3.0}])
def test_batched_risks_equal_one_scene_per_step(overrides: dict[str, float]) -> None:
    w = _wagner(**overrides)
    ref = _reference(w)
    cache: dict[int, float] = {}
    ks = list(range(w.t.shape[0]))
    assert w.first_reaching(ks, math.inf, cache) is None  # never reached: every step computed
    assert [cache[k] for k in ks] == ref  # bit for bit
    assert any(r > 0 for r in ref) or overrides == {"dv": -1.0}


@settings(max_examples=25, deadline=None)
@given(level=st.floats(0.0, 1.0), gap=st.floats(3.0, 30.0), dv=st.floats(-2.0, 8.0),
       first_block=st.integers(1, 20), start=st.integers(0, 40))
def test_first_reaching_is_the_first_step_at_or_above_the_level(
        level: float, gap: float, dv: float, first_block: int, start: int) -> None:
    w = _wagner(gap=gap, dv=dv)
    ref = np.asarray(_reference(w))
    ks = list(range(min(start, w.t.shape[0] - 1), w.t.shape[0]))
    cache: dict[int, float] = {}
    hit = w.first_reaching(ks, level, cache, first_block=first_block)
    above = [i for i, k in enumerate(ks) if ref[k] >= level]
    assert hit == (above[0] if above else None)
    # everything computed is the reference's value; nothing after the hit was needed
    for k, r in cache.items():
        assert r == ref[k]
    if hit is not None:
        assert all(k in cache for k in ks[:hit + 1])
