"""Scoring many samples: order, pool = serial, errors per sample, the real riskcore."""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor

import pandas as pd
import pytest

from datasets.cutin_model import PARAM_NAMES
from riskcore.criticality import evaluate_criticality
from sampler import SamplerError, score_samples
from sampler.scenario.builder import build_scenario
from tests.sampler.factories import base_params

#: what the Wagner scan adds to a record (score_vector(wagner_scan=True))
SCAN_FIELDS = ("alarm_time", "risk_peak", "r_dep_cross", "r_ind_cross", "r_dep_cross_r157",
               "r_ind_cross_r157")


def _rows(n: int) -> pd.DataFrame:
    return pd.DataFrame([base_params(gap=5.0 + i, dv=1.0 + 0.1 * i) for i in range(n)])


def test_serial_order_and_values() -> None:
    rows = _rows(3)
    out = score_samples(rows, chunk_size=2, include_scenarios=True)
    assert [s.index for s in out] == list(range(3))
    for i, s in enumerate(out):
        assert s.params["gap"] == 5.0 + i and s.error is None
        assert s.ttc == pytest.approx((5.0 + i) / (1.0 + 0.1 * i), rel=1e-12)
        assert s.scenario is not None and s.scenario["provenance"]["sample_index"] == i
        # the record's scores are riskcore's criticality of the builder's scenario,
        # without the Wagner scan unless asked for
        direct = evaluate_criticality(build_scenario(rows.iloc[i].to_dict()),
                                      wagner_scan=False).to_record()
        assert s.scores() == direct
        assert s.alarm_time is None and s.risk_peak is None and s.r_dep_cross is None
    full = score_samples(rows, chunk_size=2, wagner_scan=True)
    for i, s in enumerate(full):
        direct = evaluate_criticality(build_scenario(rows.iloc[i].to_dict())).to_record()
        assert s.scores() == direct and s.risk_peak is not None
        # the scan adds its two fields and changes nothing else
        assert {k: v for k, v in s.scores().items() if k not in SCAN_FIELDS} \
            == {k: v for k, v in out[i].scores().items() if k not in SCAN_FIELDS}


def test_pool_equals_serial() -> None:
    rows = _rows(4)
    serial = score_samples(rows, chunk_size=2)
    with ProcessPoolExecutor(max_workers=2) as pool:
        pooled = score_samples(rows, chunk_size=2, executor=pool)
    assert pooled == serial


def test_bad_sample_does_not_stop_the_batch() -> None:
    rows = _rows(3)
    rows.loc[1, "p_y1"] = 0.0
    out = score_samples(rows)
    assert out[1].error is not None and out[1].error.startswith("build: ")
    assert "p_y1" in out[1].error and out[1].btn is None
    assert out[0].error is None and out[2].error is None and out[0].scenario is None
    assert all(v is None for v in out[1].scores().values())


def test_real_criticality_ranks_a_closing_cut_in_higher() -> None:
    safe = base_params(dv=-2.0, gap=30.0)  # opening, far ahead
    risky = base_params(dv=6.0, gap=4.0)  # closing fast, close: ttc 0.67 s
    s_safe, s_risky = score_samples([safe, risky], wagner_scan=True)
    assert s_safe.class_ == "no_conflict" and s_safe.btn == 0.0 and not s_safe.none_collision
    assert s_risky.none_collision and s_risky.btn is not None and s_risky.btn > 0.0
    assert s_risky.risk_peak is not None and s_safe.risk_peak is not None
    assert s_risky.risk_peak > s_safe.risk_peak
    assert math.isinf(s_safe.ttc)  # opening gap: +inf, "Infinity" in JSON
    assert '"ttc":"Infinity"' in s_safe.model_dump_json()


@pytest.mark.parametrize(("kwargs", "fragment"), [({"chunk_size": 0}, "chunk_size"),
                                                  ({"chunk_size": 1.5}, "chunk_size")])
def test_bad_arguments(kwargs: dict[str, object], fragment: str) -> None:
    with pytest.raises(SamplerError, match=fragment):
        score_samples(_rows(1), **kwargs)  # type: ignore[arg-type]
    with pytest.raises(SamplerError, match="missing column"):
        score_samples(_rows(1).drop(columns=list(PARAM_NAMES[:1])))
