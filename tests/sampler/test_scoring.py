"""Scoring glue: order, pool = serial, errors per sample, the real riskcore."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from datasets.cutin_model import PARAM_NAMES
from riskcore.scenario import ConcreteScenario
from sampler import SamplerError, score_samples
from tests.sampler.factories import base_params


def fake_scorer(scenario: ConcreteScenario) -> dict[str, float]:
    """Picklable stand-in for riskcore: the gap at the recorded crossing moment."""
    t_c = scenario.provenance["t_cross"]
    x_e = float(np.interp(t_c, scenario.t, scenario.ego.x))
    x_c = float(np.interp(t_c, scenario.t, scenario.objects[0].x))
    return {"gap": x_c - x_e - 4.5, "index": scenario.provenance["sample_index"]}


def _rows(n: int) -> pd.DataFrame:
    return pd.DataFrame([base_params(gap=5.0 + i, dv=1.0 + 0.1 * i) for i in range(n)])


def test_serial_order_and_values() -> None:
    out = score_samples(_rows(7), scorer=fake_scorer, chunk_size=3)
    assert [s.index for s in out] == list(range(7))
    for i, s in enumerate(out):
        assert s.risk["index"] == i
        assert s.risk["gap"] == pytest.approx(5.0 + i, abs=1e-3)
        assert s.params["gap"] == 5.0 + i and s.error is None
        assert s.scenario is not None and s.scenario.provenance["sample_index"] == i


def test_pool_equals_serial() -> None:
    rows = _rows(6)
    serial = score_samples(rows, scorer=fake_scorer, chunk_size=2)
    pooled = score_samples(rows, scorer=fake_scorer, chunk_size=2, n_workers=2)
    assert [s.risk for s in pooled] == [s.risk for s in serial]
    assert [s.scenario for s in pooled] == [s.scenario for s in serial]


def test_bad_sample_does_not_stop_the_batch() -> None:
    rows = _rows(3)
    rows.loc[1, "p_y1"] = 0.0
    out = score_samples(rows, scorer=fake_scorer, keep_scenarios=False)
    assert out[1].error is not None and "p_y1" in out[1].error and out[1].risk is None
    assert out[0].error is None and out[2].error is None and out[0].scenario is None
    assert out[1].summary() == {"error": out[1].error}


def test_real_riskcore_scores_a_closing_cut_in_higher() -> None:
    safe = base_params(dv=-2.0, gap=30.0)  # opening, far ahead
    risky = base_params(dv=6.0, gap=4.0)  # closing fast, close: ttc 0.67 s
    out = score_samples([safe, risky])
    s_safe, s_risky = (o.summary() for o in out)
    assert s_risky["risk"] > s_safe["risk"]
    assert s_risky["min_ttc"] < 1.0
    safe_ttc = s_safe["min_ttc"]  # no closing: infinite (None in the JSON-ready summary)
    assert safe_ttc is None or math.isinf(safe_ttc) or safe_ttc > s_risky["min_ttc"]


@pytest.mark.parametrize(("kwargs", "fragment"), [({"n_workers": 0}, "n_workers"),
                                                  ({"chunk_size": 0}, "chunk_size"),
                                                  ({"n_workers": 2, "mp_context": "nope"},
                                                   "mp_context")])
def test_bad_arguments(kwargs: dict[str, object], fragment: str) -> None:
    with pytest.raises(SamplerError, match=fragment):
        score_samples(_rows(1), scorer=fake_scorer, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(SamplerError, match="missing column"):
        score_samples(_rows(1).drop(columns=list(PARAM_NAMES[:1])), scorer=fake_scorer)


def test_summary_only_keeps_the_summary_dict() -> None:
    rows = [base_params(dv=6.0, gap=4.0)]
    full = score_samples(rows)[0]
    small = score_samples(rows, summary_only=True, keep_scenarios=False)[0]
    assert isinstance(small.risk, dict)
    assert small.summary() == full.summary() == full.risk.summary()
