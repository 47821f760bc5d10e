"""Weight roulette in a campaign's final stage (``evaluate(..., roulette=K)``): a draw
whose weight ``w = p / q`` is below ``t = K * P_hat`` is run with probability ``w / t``
and then weighs ``t`` (Kahn 1956's Russian roulette).

Proven three ways: the threshold, the keep probabilities and the weights recomputed by
hand from the stored chunks; the estimate unbiased and covering on a closed-form
half-space (40 campaigns, two factors); invariants that hold for any seed (hypothesis);
and resume is byte-identical."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sampler import CutInGMM
from sampler.campaign import MAX_ROULETTE, evaluate, halfspace_runner
from sampler.campaign.evaluate import CampaignResult, ChunkResult
from sampler.errors import SamplerError
from tests.sampler.factories import synthetic_parameter_table
from tests.sampler.test_campaign import _assert_unbiased_and_covering, _Counting, _rare_halfspace


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


def _campaign(model: CutInGMM, seed: int, kappa: float = 5.0, n: int = 1500
              ) -> CampaignResult:
    a, b, _ = _rare_halfspace(model, 1e-4)
    return evaluate(model, halfspace_runner(model, a, b), n=n, seed=seed, batch_size=300,
                    physical_bounds=False, bootstrap=False, adapt="ce", ce_min_hits=5,
                    roulette=kappa)


def _threshold_by_hand(previous: list[ChunkResult], kappa: float) -> float:
    """kappa times the mean of w c over the earlier counted chunks (all of them while
    none is counted)."""
    used = [c for c in previous if c.counted] or previous
    total = 0.0
    for c in used:
        for i in range(c.n):
            if c.simulated[i] and c.outcome["collided"][i]:
                total += float(c.weights[i])
    return kappa * total / sum(c.n for c in used)


def _check_chunks(r: CampaignResult, kappa: float) -> int:
    """Every invariant of the roulette on one campaign; returns the rows it skipped."""
    skipped = 0
    for k, c in enumerate(r.chunks):
        if not c.counted or k == 0:
            assert c.roulette_t == 0.0 and c.log_keep is None and c.skipped == 0
            continue
        t = _threshold_by_hand(r.chunks[:k], kappa)
        assert t > 0 and math.isclose(c.roulette_t, t, rel_tol=1e-12)
        assert c.log_keep is not None
        keep = np.exp(c.log_keep)
        # the proposal's own weight: the stored log_q holds log q + log keep
        w_raw = np.exp(c.log_p - (c.log_q - c.log_keep))
        np.testing.assert_allclose(keep, np.minimum(1.0, w_raw / t), rtol=1e-12)
        # every row at or above the threshold was run (no region here: all inside)
        assert bool(np.all(c.simulated[w_raw >= t]))
        # a row that was run weighs its own weight or the threshold, whichever is larger
        run = c.simulated
        np.testing.assert_allclose(c.weights[run], np.maximum(w_raw[run], t), rtol=1e-12)
        assert c.skipped == int(np.count_nonzero(~run))
        skipped += c.skipped
    return skipped


def test_roulette_threshold_keep_probability_and_weights_by_hand(model: CutInGMM) -> None:
    r = _campaign(model, seed=1)
    skipped = _check_chunks(r, 5.0)
    s = r.summary()
    assert skipped > 0 and s["skipped_runs"] == skipped and s["roulette"] == 5.0
    # SUT runs are the draws that were run; the draws all count in the mean
    assert s["sut_runs"] == s["runs"] - skipped and s["runs"] == 1500
    # the estimate by hand from the records: mean of weight x collided over counted rows
    recs = [x for x in r.records() if x["counted"]]
    by_hand = sum(x["weight"] for x in recs if x["collided"] and x["simulated"]) / len(recs)
    assert math.isclose(s["p_collision"]["estimate"], by_hand, rel_tol=1e-12)
    # the records say each row's keep probability in the chunks that used the roulette
    final = [x for x in recs if "keep_prob" in x]
    assert final and all(0 < x["keep_prob"] <= 1 for x in final)
    assert any(x["keep_prob"] < 1 and not x["simulated"] for x in final)


def test_roulette_keeps_rows_with_their_probability(model: CutInGMM) -> None:
    """Over the rows below the threshold of several campaigns, the number run matches
    the sum of their keep probabilities (a sum of independent Bernoulli draws)."""
    kept, expected, var = 0, 0.0, 0.0
    for seed in range(3):
        for c in _campaign(model, seed=seed).chunks:
            if c.log_keep is None:
                continue
            pi = np.exp(c.log_keep)
            low = pi < 1
            kept += int(np.count_nonzero(c.simulated[low]))
            expected += float(pi[low].sum())
            var += float((pi[low] * (1 - pi[low])).sum())
    assert expected > 50
    assert abs(kept - expected) <= 4 * math.sqrt(var)


def test_without_roulette_every_row_is_run(model: CutInGMM) -> None:
    r = _campaign(model, seed=1, kappa=0.0)
    assert all(c.roulette_t == 0 and c.log_keep is None for c in r.chunks)
    s = r.summary()
    assert s["sut_runs"] == s["runs"] and s["skipped_runs"] == 0 and s["roulette"] == 0.0


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.5, 5.0, 40.0]))
def test_roulette_invariants_hold_for_any_seed(model: CutInGMM, seed: int,
                                               kappa: float) -> None:
    r = _campaign(model, seed=seed, kappa=kappa, n=900)
    _check_chunks(r, kappa)
    s = r.summary()
    assert s["sut_runs"] + s["skipped_runs"] == s["runs"]


@pytest.mark.slow
@pytest.mark.parametrize("kappa", [5.0, 50.0])
def test_roulette_campaign_is_unbiased_and_covering(model: CutInGMM, kappa: float) -> None:
    """40 campaigns on a half-space of known mass 1e-4 with the roulette: the mean of the
    estimates within 3 standard errors of P and the interval covering in >= 34 (any
    threshold keeps the estimate unbiased; a large one only costs variance)."""
    a, b, p_true = _rare_halfspace(model, 1e-4)
    summaries = _assert_unbiased_and_covering(
        model, halfspace_runner(model, a, b), p_true, n=1500, batch_size=300, adapt="ce",
        ce_min_hits=5, roulette=kappa)
    assert all(s["skipped_runs"] > 0 for s in summaries)


def test_roulette_resume_is_byte_identical(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 1e-4)
    opts = {"seed": 11, "n": 1500, "batch_size": 300, "physical_bounds": False,
            "bootstrap": False, "adapt": "ce", "ce_min_hits": 5, "roulette": 5.0}
    stored: list[str] = []
    first = evaluate(model, halfspace_runner(model, a, b),
                     on_chunk=lambda c: stored.append(json.dumps(c.to_dict())), **opts)
    assert first.summary()["skipped_runs"] > 0
    assert any("log_keep" in json.loads(t) for t in stored[:3])
    counting = _Counting(halfspace_runner(model, a, b))
    again = evaluate(model, counting, stored=[json.loads(t) for t in stored[:3]], **opts)
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(first.summary(),
                                                                     sort_keys=True)
    for c1, c2 in zip(first.chunks, again.chunks, strict=True):
        assert np.array_equal(c1.weights, c2.weights)
        assert np.array_equal(c1.simulated, c2.simulated)
    # only the chunks after the stored ones were run again
    assert counting.rows == first.sut_runs - sum(int(c.simulated.sum())
                                                 for c in first.chunks[:3])


@pytest.mark.parametrize("bad", [-1.0, MAX_ROULETTE * 2, math.nan, True, "5"])
def test_a_bad_roulette_factor_names_the_field(model: CutInGMM, bad: object) -> None:
    a, b, _ = _rare_halfspace(model, 1e-4)
    with pytest.raises(SamplerError, match="roulette") as err:
        evaluate(model, halfspace_runner(model, a, b), n=10, roulette=bad,  # type: ignore[arg-type]
                 physical_bounds=False, bootstrap=False)
    assert err.value.field == "roulette"
