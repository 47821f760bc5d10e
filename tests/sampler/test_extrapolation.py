"""The extrapolation cap (issue 12 item 4): density_pct, the share of the model's physical
cut-ins less probable than a vector, as a constraint quantity."""

from __future__ import annotations

import numpy as np
import pytest

from sampler import ConstraintError
from sampler.model.gmm import CutInGMM
from sampler.model.support import density_percentile
from sampler.region.constraints import Region
from sampler.sampling import sample
from tests.sampler.factories import synthetic_parameter_table


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    table = synthetic_parameter_table(300, seed=4)
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)


def test_density_pct_against_a_slow_reference(model: CutInGMM) -> None:
    """Its definition computed independently: the share of 60,000 other physical draws of
    the model (another seed) whose density is below each vector's."""
    rng = np.random.default_rng(99)
    x = model.sample(60_000, rng)
    ref = model.log_density(x[Region(lane_width=model.lane_width_).in_bounds(
        model.params_matrix(x))])
    probe = model.params_matrix(model.sample(200, np.random.default_rng(3)))
    lp = model.log_density(probe)  # the features are the 8 parameters, in order
    slow = np.array([np.mean(ref < v) for v in lp])
    fast = density_percentile(model, probe)
    assert np.max(np.abs(fast - slow)) < 0.02  # two Monte Carlo references of 2e4 and 6e4
    assert fast.min() >= 0.0 and fast.max() <= 1.0
    # monotone in the density
    order = np.argsort(lp)
    assert np.all(np.diff(fast[order]) >= 0)


def test_density_pct_caps_extrapolation(model: CutInGMM) -> None:
    plain = sample(model, ["ttc<8"], 200, seed=1)
    capped = sample(model, ["ttc<8", "density_pct>0.05"], 200, seed=1)
    pct = capped.derived["density_pct"].to_numpy()
    assert (pct > 0.05).all() and (capped.derived["ttc"] < 8).all()
    # the plain set has samples below the cap, the capped region has less mass
    assert (plain.derived["density_pct"] <= 0.05).any()
    assert capped.p_region.estimate < plain.p_region.estimate
    again = sample(model, ["ttc<8", "density_pct>0.05"], 200, seed=1)
    assert again.params.equals(capped.params)  # deterministic


def test_density_pct_needs_the_model() -> None:
    region = Region.from_constraints(["density_pct>0.1"])
    with pytest.raises(ConstraintError, match="density_pct needs the model"):
        region.contains(np.zeros((1, 8)))
