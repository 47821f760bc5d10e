"""The model on the embedded real table: existence and shape only (it may be re-fitted)."""

from __future__ import annotations

import numpy as np
import pytest

from datasets.cutin_model import PARAM_NAMES
from datasets.embedded import default_parameter_table
from sampler import CutInGMM, sample


@pytest.mark.slow
def test_fit_and_sample_on_the_embedded_table() -> None:
    table = default_parameter_table()
    assert len(table) > 50 and set(PARAM_NAMES) <= set(table.columns)
    model = CutInGMM(k_range=(1, 3), n_init=1, n_report_samples=2000).fit(table)
    assert len(model.bic_curve_) == 3 and 1 <= model.n_components_ <= 3
    assert model.lane_width_ > 0
    r = model.fit_report_
    assert set(r["ks"]) == set(PARAM_NAMES) and r["heldout_loglik_per_row"]["mean"] is not None
    back = CutInGMM.from_json(model.to_json())
    x = model.sample(100, np.random.default_rng(0))
    np.testing.assert_array_equal(back.log_density(x), model.log_density(x))
    ss = sample(model, ["ttc<3"], 50, seed=1)
    assert len(ss) == 50 and (ss.derived["ttc"] < 3).all()
    assert 0 < ss.p_region.ci_low <= ss.p_region.estimate <= ss.p_region.ci_high < 1
