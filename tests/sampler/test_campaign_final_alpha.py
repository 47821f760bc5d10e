"""The model's own defensive share in a cross-entropy campaign's final stage
(``evaluate(..., final_alpha=...)``): the pilot keeps ``alpha``, the final stage draws
the model with ``final_alpha``, every final-stage weight stays below ``1 / final_alpha``,
the estimate stays unbiased, and the no-collision bound uses the share of the chunks it
counts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sampler import CutInGMM
from sampler.campaign import ROULETTE_FINAL_ALPHA, evaluate, halfspace_runner
from sampler.campaign.evaluate import CampaignResult, next_ce_proposal
from sampler.errors import SamplerError
from tests.sampler.factories import synthetic_parameter_table
from tests.sampler.test_campaign import _assert_unbiased_and_covering, _rare_halfspace


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


def _model_share(proposal: list[dict[str, object]]) -> float:
    [share] = [float(p["share"]) for p in proposal if p["part"] == "model"]  # type: ignore[arg-type]
    return share


def _campaign(model: CutInGMM, seed: int, **kw: object) -> CampaignResult:
    a, b, _ = _rare_halfspace(model, 1e-4)
    opts: dict[str, object] = {"n": 1500, "batch_size": 300, "physical_bounds": False,
                               "bootstrap": False, "adapt": "ce", "ce_min_hits": 5,
                               "roulette": 5.0, "final_alpha": 0.05}
    opts.update(kw)
    return evaluate(model, halfspace_runner(model, a, b), seed=seed, **opts)  # type: ignore[arg-type]


def test_the_pilot_keeps_alpha_and_the_final_stage_takes_final_alpha(model: CutInGMM
                                                                     ) -> None:
    r = _campaign(model, seed=1)
    assert r.alpha == 0.15 and r.final_alpha == 0.05
    counted = [c for c in r.chunks if c.counted]
    pilot = [c for c in r.chunks if not c.counted]
    assert counted and pilot  # both stages ran
    for c in pilot:
        assert _model_share(c.proposal) == pytest.approx(0.15, rel=1e-12)
    for c in counted:
        assert _model_share(c.proposal) == pytest.approx(0.05, rel=1e-12)
        # q >= 0.05 p everywhere: the proposal's own weight (the roulette's keep
        # probability taken out of the stored log q) is at most 1 / 0.05
        assert c.log_keep is not None
        w_raw = np.exp(c.log_p - (c.log_q - c.log_keep))
        assert float(w_raw.max()) <= 1 / 0.05 * (1 + 1e-9)
    s = r.summary()
    assert s["alpha"] == 0.15 and s["final_alpha"] == 0.05
    assert r.bound_alpha == 0.05
    # the diagnostic rebuild of the next proposal takes the same share
    nxt = next_ce_proposal(r, alpha=0.15, ce_min_hits=5, final_alpha=0.05)
    assert _model_share(nxt.describe()) == pytest.approx(0.05, rel=1e-12)


def test_without_final_alpha_the_final_stage_keeps_alpha(model: CutInGMM) -> None:
    r = _campaign(model, seed=1, final_alpha=None)
    assert r.final_alpha is None and r.summary()["final_alpha"] is None
    assert all(_model_share(c.proposal) == pytest.approx(0.15, rel=1e-12)
               for c in r.chunks[1:])
    assert r.bound_alpha == 0.15
    # the same campaign with the same share given explicitly: bit for bit the same chunks
    same = _campaign(model, seed=1, final_alpha=0.15)
    for c1, c2 in zip(r.chunks, same.chunks, strict=True):
        assert c1.weights.tobytes() == c2.weights.tobytes()


def test_final_alpha_campaign_is_unbiased_and_covering(model: CutInGMM) -> None:
    """40 campaigns on a half-space of known mass 1e-4 (mean within 3 standard errors,
    the interval covering in >= 34)."""
    a, b, p_true = _rare_halfspace(model, 1e-4)
    summaries = _assert_unbiased_and_covering(
        model, halfspace_runner(model, a, b), p_true, n=1500, batch_size=300, adapt="ce",
        ce_min_hits=5, roulette=5.0, final_alpha=ROULETTE_FINAL_ALPHA)
    assert all(s["final_alpha"] == 0.05 for s in summaries)


def test_a_campaign_without_a_collision_keeps_the_pilot_bound(model: CutInGMM) -> None:
    """No collision: no final stage, every chunk is a pilot chunk with the model's share
    ``alpha``, so the bound is -ln(0.05) / (alpha N), not the final share's."""
    a = np.zeros(model.n_features)
    a[model.features_.index("gap")] = 1.0
    never = halfspace_runner(model, a, -1e9)  # gap below -1e9: nobody
    r = evaluate(model, never, n=900, seed=0, batch_size=300, physical_bounds=False,
                 bootstrap=False, adapt="ce", roulette=5.0, final_alpha=0.05)
    assert not any(c.counted for c in r.chunks)
    assert r.bound_alpha == 0.15
    s = r.summary()["p_collision"]
    assert s["hits"] == 0
    assert s["upper_bound"] == pytest.approx(-math.log(0.05) / (0.15 * 900), rel=1e-12)


def test_final_alpha_resume_is_byte_identical(model: CutInGMM) -> None:
    stored: list[str] = []
    first = _campaign(model, seed=11, on_chunk=lambda c: stored.append(
        json.dumps(c.to_dict())))
    again = _campaign(model, seed=11, stored=[json.loads(t) for t in stored[:3]])
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(first.summary(),
                                                                     sort_keys=True)


@pytest.mark.parametrize("bad", [0, -0.1, 0.5, "small", True, math.nan])
def test_a_bad_final_alpha_names_the_field(model: CutInGMM, bad: object) -> None:
    with pytest.raises(SamplerError) as e:
        _campaign(model, seed=0, n=10, final_alpha=bad)
    assert e.value.field == "final_alpha"
