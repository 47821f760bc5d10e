"""Model-level figures (P(B), the bootstrap model interval) are estimated once per model."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sampler.model import memo
from sampler.model.bootstrap import bootstrap_fit
from sampler.model.gmm import CutInGMM
from sampler.rates.exposure import Exposure, region_report
from sampler.sampling import sample
from tests.sampler.factories import synthetic_parameter_table


def _model() -> tuple[CutInGMM, pd.DataFrame]:
    table = synthetic_parameter_table(300, seed=0)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)
    return model, table


def test_memoised_computes_once_per_key_and_clear_forgets() -> None:
    model, _ = _model()
    calls: list[int] = []

    def compute() -> int:
        calls.append(1)
        return len(calls)

    assert memo.memoised(model, "k", compute) == 1
    assert memo.memoised(model, "k", compute) == 1
    assert memo.memoised(model, "other", compute) == 2
    memo.clear(model)
    assert memo.memoised(model, "k", compute) == 3
    for i in range(memo.MAX_ENTRIES + 5):  # bounded
        memo.memoised(model, ("n", i), lambda: 0)
    assert len(model.__dict__["_scengen_memo"]) == memo.MAX_ENTRIES


@pytest.mark.slow
def test_p_bounds_is_a_model_figure_and_samples_do_not_change() -> None:
    model, _ = _model()
    fresh = CutInGMM.from_json(model.to_json())
    a = sample(model, ["ttc<8"], 50, seed=1)
    b = sample(model, ["ttc<8"], 50, seed=2)
    # the same P(B) whatever the request's seed ...
    assert a.p_region.p_bounds == b.p_region.p_bounds
    assert a.p_region.p_bounds_ci == b.p_region.p_bounds_ci
    # ... and the same as a model object that has memoised nothing computes
    c = sample(fresh, ["ttc<8"], 50, seed=1)
    assert c.p_region.p_bounds == a.p_region.p_bounds
    # the samples of a seed do not depend on whether P(B) was memoised
    np.testing.assert_array_equal(c.params.to_numpy(), a.params.to_numpy())
    again = sample(model, ["ttc<8"], 50, seed=1)
    np.testing.assert_array_equal(again.params.to_numpy(), a.params.to_numpy())
    assert again.p_region == a.p_region


@pytest.mark.slow
def test_model_interval_is_memoised_per_region_and_replicate_set() -> None:
    model, table = _model()
    bootstrap_fit(model, table, 10, seed=0)
    model.exposure_ = Exposure(n_events=300, hours=25.0, km=None, source="t").to_dict()
    ss1 = sample(model, ["ttc<8"], 100, seed=1)
    ss2 = sample(model, ["ttc<8"], 100, seed=2)
    r1, r2 = region_report(model, ss1), region_report(model, ss2)
    assert r1["model_interval"] == r2["model_interval"]  # not the request's seed
    assert r1["rates"]["per_hour"]["model_ci"] == r2["rates"]["per_hour"]["model_ci"]
    # a model object with nothing memoised computes the same
    fresh = CutInGMM.from_json(model.to_json())
    assert region_report(fresh, ss1) == r1
    # callers get copies: changing one does not change the memo
    r1["model_interval"]["ci"][0] = -1.0
    assert region_report(model, ss1)["model_interval"]["ci"][0] != -1.0
    # new replicates: a new interval
    bootstrap_fit(model, table, 12, seed=5)
    r3 = region_report(model, ss1)
    assert r3["model_interval"]["n_boot"] == 12
    assert r3["model_interval"]["replicates"] != r2["model_interval"]["replicates"]
