"""sampler.campaign, adaptive cross-entropy stage (``evaluate(adapt="ce")``).

The weighted EM's one-component fit is the weighted mean and covariance, worked out by
hand below; the mixture's densities are checked against scipy's own normal and Student-t
densities; the campaign's estimate is checked on a half-space whose mass is known in
closed form (scipy's normal CDF over the model's mixture, as tests/sampler/test_campaign.py).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from sampler import CutInGMM
from sampler.campaign import evaluate, halfspace_runner, union_probability, union_runner
from sampler.campaign.evaluate import performance_score
from sampler.campaign.proposal import (
    DEFAULT_ENVELOPES,
    GaussianMixture,
    build_ce_proposal,
    fit_ce_mixture,
    fit_weighted_gmm,
    region_mixture,
)
from sampler.errors import SamplerError
from sampler.region import Region
from tests.sampler.factories import synthetic_parameter_table
from tests.sampler.test_campaign import (
    _assert_unbiased_and_covering,
    _Counting,
    _mass,
    _rare_halfspace,
)


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


def test_one_component_weighted_em_is_the_weighted_mean_and_covariance() -> None:
    z = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    w = np.array([2.0, 1.0, 1.0])
    gm, _ = fit_weighted_gmm(z, w, 1, np.random.default_rng(0), floor=0.01)
    # by hand: weights 1/2, 1/4, 1/4 -> mean (0.5, 0.5); deviations (-.5,-.5),
    # (1.5,-.5), (-.5,1.5): var = .5*.25 + .25*2.25 + .25*.25 = .75,
    # cov = .5*.25 + .25*(-.75) + .25*(-.75) = -.25; plus the floor .01 on the diagonal
    assert np.allclose(gm.means, [[0.5, 0.5]])
    assert np.allclose(gm.covs[0], [[0.76, -0.25], [-0.25, 0.76]])
    assert np.allclose(gm.weights, [1.0])


def test_weighted_em_separates_two_clusters() -> None:
    rng = np.random.default_rng(1)
    z = np.concatenate([rng.normal(-5, 0.3, (200, 2)), rng.normal(5, 0.3, (100, 2))])
    w = np.concatenate([np.full(200, 1.0), np.full(100, 4.0)])  # mass 200 : 400
    gm, _ = fit_weighted_gmm(z, w, 2, np.random.default_rng(2), floor=1e-6)
    order = np.argsort(gm.means[:, 0])
    assert np.allclose(gm.weights[order], [1 / 3, 2 / 3], atol=1e-6)
    assert np.allclose(gm.means[order, 0], [z[:200, 0].mean(), z[200:, 0].mean()])


def test_mixture_densities_match_scipy_and_draws_follow_them() -> None:
    means = np.array([[0.0, 1.0], [3.0, -1.0]])
    covs = np.array([[[1.0, 0.3], [0.3, 0.5]], [[0.4, 0.0], [0.0, 2.0]]])
    w = np.array([0.3, 0.7])
    pts = np.random.default_rng(3).normal(0, 2, (50, 2))
    for nu in (math.inf, 5.0):
        gm = GaussianMixture(w, means, covs, nu=nu)
        if math.isinf(nu):
            ref = sum(wk * stats.multivariate_normal(m, c).pdf(pts)
                      for wk, m, c in zip(w, means, covs, strict=True))
        else:
            ref = sum(wk * stats.multivariate_t(m, c, df=nu).pdf(pts)
                      for wk, m, c in zip(w, means, covs, strict=True))
        assert np.allclose(np.exp(gm.log_q(pts)), ref, rtol=1e-10)
        x = gm.draw(40000, np.random.default_rng(4))
        assert abs(x[:, 0].mean() - (w @ means[:, 0])) < 0.05


def test_ce_mixture_has_a_component_on_each_model_component(model: CutInGMM) -> None:
    rng = np.random.default_rng(5)
    z = model.sample_z(400, rng)
    gm = fit_ce_mixture(z, np.ones(400), np.random.default_rng(6), model=model, max_k=1)
    # one EM component plus one per model component (K = 2), Student-t(5)
    assert gm.weights.size == 1 + model.n_components_ and gm.nu == 5.0
    assert math.isclose(float(gm.weights.sum()), 1.0)


def test_performance_score_by_hand() -> None:
    out = {"collided": np.array([True, False, False, False, True]),
           "impact_speed": np.array([3.0, 0.0, 0.0, 0.0, 2.0]),
           "min_gap": np.array([0.0, 4.5, np.nan, np.inf, 0.0])}
    sim = np.array([True, True, True, True, False])
    s = performance_score(out, sim)
    assert s is not None
    # collided: -impact speed; else the smallest gap; NaN, inf, not simulated: inf
    assert s.tolist() == [-3.0, 4.5, math.inf, math.inf, math.inf]
    assert performance_score({"collided": sim, "impact_speed": np.zeros(5)}, sim) is None


@pytest.mark.slow
def test_ce_campaign_is_unbiased_and_covers_on_a_closed_form_case(model: CutInGMM) -> None:
    a, b, p_true = _rare_halfspace(model, 3e-5)
    summaries = _assert_unbiased_and_covering(model, halfspace_runner(model, a, b), p_true,
                                              n=1200, batch_size=300, adapt="ce")
    # the first chunk of every campaign is a pilot
    assert all(summ["pilot_runs"] >= 300 for summ in summaries)


def test_ce_estimate_uses_the_final_stage_only(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 1e-4)
    r = evaluate(model, halfspace_runner(model, a, b), n=1500, seed=1, batch_size=300,
                 physical_bounds=False, bootstrap=False, adapt="ce", ce_min_hits=5)
    counted = [c.counted for c in r.chunks]
    assert counted[0] is False and counted[-1] is True
    first = counted.index(True)
    # a chunk is counted once the chunks before it hold >= 5 collided runs
    assert sum(int(c.collided.sum()) for c in r.chunks[:first]) >= 5
    assert sum(int(c.collided.sum()) for c in r.chunks[:first - 1]) < 5
    assert all(counted[first:])
    # the estimate by hand from the records: mean of weight x collided over counted rows
    recs = [x for x in r.records() if x["counted"]]
    by_hand = sum(x["weight"] for x in recs if x["collided"] and x["simulated"]) / len(recs)
    s = r.summary()
    assert math.isclose(s["p_collision"]["estimate"], by_hand, rel_tol=1e-12)
    assert s["pilot_runs"] == 300 * first and s["adapt"] == "ce"
    assert any(p["part"].startswith("ce:") for p in s["proposal"])


def test_ce_resume_is_byte_identical_and_deterministic(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 3e-5)
    stored: list[str] = []
    first = evaluate(model, halfspace_runner(model, a, b), seed=11, batch_size=300,
                     physical_bounds=False, bootstrap=False, adapt="ce",
                     on_chunk=lambda c: stored.append(json.dumps(c.to_dict())))
    assert len(stored) >= 3
    counting = _Counting(halfspace_runner(model, a, b))
    again = evaluate(model, counting, seed=11, batch_size=300, physical_bounds=False,
                     bootstrap=False, adapt="ce", stored=[json.loads(t) for t in stored[:2]])
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(first.summary(),
                                                                     sort_keys=True)
    assert counting.rows == first.sut_runs - sum(int(c.simulated.sum())
                                                 for c in first.chunks[:2])
    assert [c.counted for c in again.chunks] == [c.counted for c in first.chunks]


@dataclass(frozen=True)
class _Unscored:
    """A runner's result with no performance score (no margin, no min_gap)."""
    collided: np.ndarray
    impact_speed: np.ndarray


def test_a_runner_without_a_score_adapts_as_kernels(model: CutInGMM) -> None:
    """The default adaptation (ce) with a runner that gives no score is the kernels'
    campaign bit for bit: the same draws, the same estimate, every chunk counted, and
    the summary says kernels (no "no final stage" warning that more draws cannot fix)."""
    a, b, _ = _rare_halfspace(model, 1e-3)
    inner = halfspace_runner(model, a, b)

    def runner(params: np.ndarray, seeds: np.ndarray) -> _Unscored:
        r = inner(params, seeds)
        return _Unscored(np.asarray(r.collided), np.asarray(r.impact_speed))

    kw: dict[str, Any] = {"n": 900, "seed": 3, "batch_size": 300,
                          "physical_bounds": False, "bootstrap": False}
    ce = evaluate(model, runner, **kw)
    ker = evaluate(model, runner, adapt="kernels", **kw)
    s_ce, s_k = ce.summary(), ker.summary()
    assert sum(int(c.collided.sum()) for c in ce.chunks) > 0
    assert s_ce["adapt"] == "kernels" and s_ce["pilot_runs"] == 0
    assert s_ce["p_collision"] == s_k["p_collision"]
    assert all(np.array_equal(c1.z, c2.z) for c1, c2 in zip(ce.chunks, ker.chunks,
                                                              strict=True))
    assert s_ce["warnings"] == s_k["warnings"]
    assert all(x["counted"] for x in ce.records())  # every chunk made the estimate
    # with the stop rule too: both stop after the same chunk
    rule: dict[str, Any] = {**kw, "n": None, "rhw": 0.9, "max_runs": 3000}
    s_ce, s_k = (evaluate(model, runner, **rule).summary(),
                 evaluate(model, runner, adapt="kernels", **rule).summary())
    assert s_k["runs"] == 300, s_k["runs"]  # kernels stops after its first chunk
    assert s_ce["runs"] == s_k["runs"] and s_ce["p_collision"] == s_k["p_collision"]
    # a runner with a score keeps the cross-entropy stage
    assert evaluate(model, inner, **kw).summary()["adapt"] == "ce"


@pytest.mark.parametrize(("kwargs", "name"), [({"adapt": "nope"}, "adapt"),
                                              ({"rho": 1.5}, "rho"),
                                              ({"ce_min_hits": 0}, "ce_min_hits")])
def test_bad_ce_settings_name_the_field(model: CutInGMM, kwargs: dict[str, object],
                                        name: str) -> None:
    with pytest.raises(SamplerError) as err:
        evaluate(model, halfspace_runner(model, np.ones(model.n_features), 0.0), n=10,
                 **kwargs)  # type: ignore[arg-type]
    assert err.value.field == name


# --------------------------------------------------------------------------- two families

def _two_families(model: CutInGMM, p_a: float, p_b: float
                  ) -> tuple[list[tuple[np.ndarray, float]], float]:
    """Two separated failure half-spaces: A along (small gap, large dv) with mass p_a and
    B a hard cutter brake (small p_a1) with mass p_b; and the union's mass by hand:
    P(A) + P(B) - P(A and B), the pair's mass per model component from scipy's bivariate
    normal CDF (Genz's algorithm: independent of the campaign's quadrature)."""
    a_a, b_a, _ = _rare_halfspace(model, p_a)
    a_b = np.zeros(model.n_features)
    a_b[model.features_.index("p_a1")] = 1.0
    lo, hi = -40.0, 0.0
    for _ in range(80):  # bisection on b
        mid = 0.5 * (lo + hi)
        if _mass(model, a_b, mid) < p_b:
            lo = mid
        else:
            hi = mid
    b_b = hi
    both = 0.0
    for w, mu, cov in zip(model.weights_, model.means_, model.covariances_, strict=True):
        m = np.array([a_a @ mu, a_b @ mu])
        c = np.array([[a_a @ cov @ a_a, a_a @ cov @ a_b], [a_a @ cov @ a_b, a_b @ cov @ a_b]])
        both += w * stats.multivariate_normal(m, c).cdf(np.array([b_a, b_b]))
    p = _mass(model, a_a, b_a) + _mass(model, a_b, b_b) - both
    return [(a_a, b_a), (a_b, b_b)], float(p)


def test_union_runner_and_its_probability(model: CutInGMM) -> None:
    hs, p_hand = _two_families(model, 2e-3, 1e-3)
    assert math.isclose(union_probability(model, hs), p_hand, rel_tol=1e-5)
    # the runner collides exactly in the union, and its margin says which side
    z = model.sample_z(20000, np.random.default_rng(8))
    params = model.params_matrix(model.from_z(z))
    out = union_runner(model, hs)(params, np.zeros(20000, dtype=np.uint64))
    in_union = np.zeros(20000, dtype=bool)
    for a, b in hs:
        in_union |= model.to_z(params[:, :model.n_features]) @ a <= b
    assert out.collided.tolist() == in_union.tolist()
    assert ((out.margin <= 0) == out.collided).all()
    # naive Monte Carlo agrees with the formula (4 standard errors)
    assert abs(out.collided.mean() - p_hand) <= 4 * math.sqrt(p_hand / 20000)


@pytest.mark.slow
def test_ce_campaign_keeps_two_failure_families(model: CutInGMM) -> None:
    """Two families of unequal mass (2.5e-5 and 5e-6): with the stop rule, the mean of
    30 campaigns is unbiased and the 95 % interval covers P in at least 26 of 30. Before
    the pilot levels' mixtures were kept in the proposal: 26 of 30 on this case, 27 of
    30 with masses 2e-5 / 1e-5 (30 of 30 after)."""
    hs, p_true = _two_families(model, 2.5e-5, 5e-6)
    runner = union_runner(model, hs)
    est, covered = [], 0
    hits_b = 0
    for s in range(30):
        r = evaluate(model, runner, seed=s, batch_size=300, physical_bounds=False,
                     bootstrap=False, adapt="ce")
        summ = r.summary()
        est.append(summ["p_collision"]["estimate"])
        lo, hi = summ["p_collision"]["ci"]
        covered += int(lo is not None and lo <= p_true <= hi)
        a_b, b_b = hs[1]
        hits_b += sum(int((c.z[c.collided] @ a_b <= b_b).sum()) for c in r.counted_chunks)
        assert any(p["part"].startswith("ce:levels") for p in summ["proposal"])
    e = np.asarray(est)
    se_mean = e.std(ddof=1) / math.sqrt(e.size)
    assert abs(e.mean() - p_true) <= 3 * se_mean
    assert abs(e.mean() / p_true - 1) < 0.1
    assert covered >= 27
    assert hits_b >= 30 * 10  # the smaller family is drawn in the final stage


#: a set with no half-space envelope that holds ~0.15 % of the synthetic model's draws
_SET = "v_cut_min<15"
# the default critical sets without the band sets (v_cut_min, end_margin): the tests give
# their own set part its whole share
_OTHER_ENVELOPES = tuple(e for e in DEFAULT_ENVELOPES
                          if not e.startswith(("v_cut_min", "end_margin")))


def test_set_part_density_is_normalised_and_sits_on_its_set(model: CutInGMM) -> None:
    """The part fitted to a set without a half-space (``region_mixture``) has an exact
    normaliser: with r = (p + q) / 2 drawn half from the model p and half from the part
    q, the mean of q / r over draws of r is the integral of q, 1 (q / r <= 2: a tight
    standard error); likewise p / r. And its draws fall in the set far more often than
    the model's."""
    reg = Region.from_constraints([_SET], lane_width=model.lane_width_)
    gm = region_mixture(model, reg)
    assert gm is not None and np.isfinite(gm.nu)
    rng = np.random.default_rng(11)
    n = 100_000
    z = np.concatenate([model.sample_z(n, rng), gm.draw(n, rng)])
    log_p = model.log_density_z(z)
    log_q = gm.log_q(z)
    log_r = np.logaddexp(log_p, log_q) - math.log(2)
    for ratio in (np.exp(log_q - log_r), np.exp(log_p - log_r)):
        se = ratio.std(ddof=1) / math.sqrt(ratio.size)
        assert abs(ratio.mean() - 1.0) <= 4 * se
        assert se < 0.005
    inside = reg.bind(model)
    frac_q = inside.contains(model.params_matrix(model.from_z(z[n:]))).mean()
    frac_p = inside.contains(model.params_matrix(model.from_z(z[:n]))).mean()
    assert frac_p < 0.01 and frac_q > 20 * frac_p
    # deterministic: the same mixture again
    again = region_mixture(model, reg)
    assert again is not None and np.array_equal(again.means, gm.means)
    # a set the model never reaches in the first block: no part
    none = Region.from_constraints(["v_cut_min<3"], lane_width=model.lane_width_)
    assert region_mixture(model, none) is None


def test_ce_proposal_with_a_set_part_keeps_the_weights_unbiased(model: CutInGMM) -> None:
    """E_q[p / q] = 1 for the whole mixture with the set part (weights <= 1 / alpha);
    the set part has its own share."""
    z_e = model.sample_z(400, np.random.default_rng(2))
    envs = (*_OTHER_ENVELOPES, _SET)
    prop = build_ce_proposal(model, region=None, lane_width=model.lane_width_,
                             elite=(z_e[:60], np.ones(60)), level=1.0,
                             rng=np.random.default_rng(3), envelopes=envs, set_share=0.1)
    shares = {d["part"]: d["share"] for d in prop.describe()}
    # a v_cut_min set is drawn by its band part (sampler.campaign.band)
    assert math.isclose(shares[f"band:{_SET}"], 0.1, rel_tol=1e-12)
    z, _ = prop.draw(200_000, np.random.default_rng(4))
    w = np.exp(model.log_density_z(z) - prop.log_q(z))
    assert w.max() <= 1 / 0.1 + 1e-9
    se = w.std(ddof=1) / math.sqrt(w.size)
    assert abs(w.mean() - 1.0) <= 4 * se


@pytest.mark.slow
def test_ce_campaign_with_a_set_part_is_unbiased_and_covers(model: CutInGMM) -> None:
    a, b, p_true = _rare_halfspace(model, 3e-5)
    summaries = _assert_unbiased_and_covering(
        model, halfspace_runner(model, a, b), p_true, n=1200, batch_size=300, adapt="ce",
        envelopes=(*_OTHER_ENVELOPES, _SET))
    assert all(any(p["part"] == f"band:{_SET}" for p in summ["proposal"])
               for summ in summaries)


def test_next_ce_proposal_is_the_one_the_next_chunk_drew_from(model: CutInGMM) -> None:
    """``next_ce_proposal`` of a campaign cut after k chunks gives the density chunk k of
    the longer campaign (same seed) used: its log q at that chunk's draws, bit for bit."""
    from sampler.campaign import next_ce_proposal

    a, b, _ = _rare_halfspace(model, 1e-3)
    runner = halfspace_runner(model, a, b)
    short = evaluate(model, runner, n=1500, seed=8, batch_size=300, adapt="ce",
                     physical_bounds=False)
    longer = evaluate(model, runner, n=1800, seed=8, batch_size=300, adapt="ce",
                      physical_bounds=False)
    nxt = longer.chunks[len(short.chunks)]
    prop = next_ce_proposal(short)
    assert np.array_equal(prop.log_q(nxt.z), nxt.log_q)
    assert prop.describe() == nxt.proposal


def test_band_step_is_opt_in_and_sets_the_final_shares(model: CutInGMM) -> None:
    """``band_step=True`` gives the final stage the band-weighted shares (the set and band
    parts ``BAND_STEP_SET_SHARE`` together, the kernels ``BAND_STEP_KERNEL_SHARE``); the
    default keeps ``FINAL_SET_SHARE`` and ``FINAL_KERNEL_SHARE``. The pilot is the same
    either way, chunk for chunk."""
    from sampler.campaign.proposal import (
        BAND_STEP_KERNEL_SHARE,
        BAND_STEP_SET_SHARE,
        FINAL_KERNEL_SHARE,
        FINAL_SET_SHARE,
    )
    a, b, _ = _rare_halfspace(model, 1e-4)
    runs = {}
    for step in (False, True):
        runs[step] = evaluate(model, halfspace_runner(model, a, b), n=1500, seed=1,
                              batch_size=300, physical_bounds=False, bootstrap=False,
                              adapt="ce", ce_min_hits=5, band_step=step)
    first = [c.counted for c in runs[False].chunks].index(True)
    for k in range(first):
        assert np.array_equal(runs[False].chunks[k].z, runs[True].chunks[k].z)
    for step, set_share, kern_share in ((False, FINAL_SET_SHARE, FINAL_KERNEL_SHARE),
                                        (True, BAND_STEP_SET_SHARE, BAND_STEP_KERNEL_SHARE)):
        last = runs[step].chunks[-1].proposal
        sets = sum(p["share"] for p in last if p["part"].startswith(("band:", "set:")))
        kern = sum(p["share"] for p in last if p["part"].startswith("fitted:"))
        assert math.isclose(sets, set_share, rel_tol=1e-9)
        assert math.isclose(kern, kern_share, rel_tol=1e-9)


# --------------------------------------------------------------------------- tuned shares

@dataclass
class _TablePart:
    """A part whose log density at the rows ``z = [[0], [1], ...]`` is read off a table."""

    name: str
    log_at: np.ndarray

    def log_q(self, z: np.ndarray) -> np.ndarray:
        return self.log_at[z[:, 0].astype(int)]

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError


def _two_hit_case(c1: float, c2: float) -> tuple[Any, ...]:
    """The model (fixed share 0.1, p = 1 at both rows) and parts A, B with g/p = 10 at one
    row each and 0 at the other; 10 collided runs at each row, weights c1 and c2."""
    ten = math.log(10.0)
    parts = [_TablePart("model", np.array([0.0, 0.0])),
             _TablePart("A", np.array([ten, -np.inf])),
             _TablePart("B", np.array([-np.inf, ten]))]
    z = np.repeat([[0.0], [1.0]], 10, axis=0)
    w = np.repeat([c1, c2], 10)
    return parts, np.array([0.1, 0.45, 0.45]), z, w, np.zeros(20), np.array([True, False, False])


def test_tuned_shares_by_hand() -> None:
    """F(s) = 10 (c1 / (0.1 + 10 s_A) + c2 / (0.1 + 10 s_B)) with s_A + s_B = 0.9. By hand
    (Lagrange): (0.1 + 10 s_A) / (0.1 + 10 s_B) = sqrt(c1 / c2); for c1 = 4, c2 = 1 the
    two sum to 9.2, so 0.1 + 10 s_B = 9.2 / 3 and s_A = (6.1333 - 0.1) / 10 = 0.60333,
    s_B = 0.29667. For c1 = 1e4 the optimum's s_B would be negative: s_B sits on its lower
    bound 0.5 * 0.45 and s_A takes the rest, 0.675. Fewer than 20 runs: unchanged."""
    from sampler.campaign.proposal import tune_shares
    parts, s0, z, w, log_p, fixed = _two_hit_case(4.0, 1.0)
    s = tune_shares(parts, s0, z, w, log_p, fixed=fixed)
    assert s[0] == pytest.approx(0.1, abs=1e-12)
    assert s[1] == pytest.approx((9.2 * 2 / 3 - 0.1) / 10, abs=1e-4)
    assert s[2] == pytest.approx((9.2 / 3 - 0.1) / 10, abs=1e-4)
    parts, s0, z, w, log_p, fixed = _two_hit_case(1e4, 1.0)
    s = tune_shares(parts, s0, z, w, log_p, fixed=fixed)
    assert s == pytest.approx([0.1, 0.675, 0.225], abs=1e-6)
    assert np.array_equal(tune_shares(parts, s0, z[:19], w[:19], log_p[:19], fixed=fixed),
                          s0)


def _second_moment(parts: list[Any], s: np.ndarray, z: np.ndarray, w: np.ndarray,
                   log_p: np.ndarray) -> float:
    """sum_i w_i p_i / q_s(z_i), straight from the definition (a loop over runs)."""
    total = 0.0
    for i in range(z.shape[0]):
        q = sum(sj * math.exp(float(part.log_q(z[i:i + 1])[0]))
                for sj, part in zip(s, parts, strict=True))
        total += w[i] * math.exp(log_p[i]) / q
    return total


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_tuned_shares_properties(seed: int) -> None:
    """For any densities and weights: the shares sum to 1, the fixed part keeps its
    share, every other part stays within [0.5, 3] times its own, and the second moment
    (computed by the loop above) is no larger than at the shares given."""
    from sampler.campaign.proposal import TUNE_HI, TUNE_LO, tune_shares
    rng = np.random.default_rng(seed)
    n, j = int(rng.integers(20, 60)), int(rng.integers(2, 6))
    parts = [_TablePart(f"p{k}", rng.normal(0.0, 3.0, n)) for k in range(j)]
    s0 = rng.dirichlet(np.ones(j))
    s0 = np.maximum(s0, 0.02)
    s0 /= s0.sum()
    z = np.arange(n, dtype=np.float64)[:, None]
    w = rng.lognormal(0.0, 2.0, n)
    log_p = rng.normal(0.0, 1.0, n)
    fixed = np.zeros(j, dtype=bool)
    fixed[0] = True
    s = tune_shares(parts, s0, z, w, log_p, fixed=fixed)
    assert s.sum() == pytest.approx(1.0, abs=1e-9)
    assert s[0] == pytest.approx(s0[0], rel=1e-12)
    assert np.all(s[1:] >= TUNE_LO * s0[1:] * (1 - 1e-6))
    assert np.all(s[1:] <= TUNE_HI * s0[1:] * (1 + 1e-6))
    assert (_second_moment(parts, s, z, w, log_p)
            <= _second_moment(parts, s0, z, w, log_p) * (1 + 1e-9))


def test_tuned_shares_campaign_is_deterministic_and_moves_the_final_shares(
        model: CutInGMM) -> None:
    """``tune_shares=True``: the pilot is the default's chunk for chunk, the final chunks'
    shares differ from the fixed ones while the model keeps ``alpha``, and the same seed
    gives the same campaign bit for bit."""
    a, b, _ = _rare_halfspace(model, 1e-4)
    runner = halfspace_runner(model, a, b)
    kw: dict[str, Any] = {"n": 1500, "seed": 1, "batch_size": 300, "physical_bounds": False,
                          "bootstrap": False, "adapt": "ce", "ce_min_hits": 5}
    fixed = evaluate(model, runner, **kw)
    tuned = evaluate(model, runner, tune_shares=True, **kw)
    again = evaluate(model, runner, tune_shares=True, **kw)
    first = [c.counted for c in fixed.chunks].index(True)
    for k in range(first):
        assert np.array_equal(fixed.chunks[k].z, tuned.chunks[k].z)
    last_f, last_t = fixed.chunks[-1].proposal, tuned.chunks[-1].proposal
    assert [p["part"].split(":")[0] for p in last_f] == [p["part"].split(":")[0]
                                                          for p in last_t]
    assert last_t[0]["part"] == "model" and last_t[0]["share"] == pytest.approx(0.15)
    assert max(abs(p["share"] - q["share"]) for p, q in zip(last_f, last_t, strict=True)) > 0.01
    assert json.dumps(tuned.summary()) == json.dumps(again.summary())
    for c1, c2 in zip(tuned.chunks, again.chunks, strict=True):
        assert np.array_equal(c1.weights, c2.weights)


@pytest.mark.slow
def test_tuned_shares_campaign_is_unbiased_and_covering(model: CutInGMM) -> None:
    """40 tuned campaigns on a half-space of known mass 1e-4 (chunks of 300, the final
    stage from the sixth collision on): unbiased and covering as the fixed shares are."""
    a, b, p_true = _rare_halfspace(model, 1e-4)
    summaries = _assert_unbiased_and_covering(
        model, halfspace_runner(model, a, b), p_true, n=1500, batch_size=300, adapt="ce",
        ce_min_hits=5, tune_shares=True)
    assert all(s["pilot_runs"] > 0 for s in summaries)
