"""Constrained sampling: rejection vs MCMC, P(A) against brute force, determinism, errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from datasets.cutin_model import PARAM_NAMES
from sampler import EmptyRegionError, SamplerError
from sampler.methods.envelope import find_envelope
from sampler.methods.mcmc import integrated_time
from sampler.methods.probability import PRegionEstimator
from sampler.methods.samplers import AutoSampler, MCMCSampler, Pilot
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region, derive
from sampler.sampling import SampleSet, estimate_p_region, sample
from tests.sampler.factories import synthetic_parameter_table

MODERATE = ["ttc<8"]  # P(A) about 0.03 on the synthetic model


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=0))


@pytest.fixture(scope="module")
def brute(model: CutInGMM) -> dict[str, tuple[int, int]]:
    """Brute-force counts (inside region, inside bounds) over 1.2M plain model draws."""
    x = model.params_matrix(model.sample(1_200_000, np.random.default_rng(2024)))
    n_b = int(Region(lane_width=model.lane_width_).in_bounds(x).sum())
    out = {}
    for c in ("ttc<8", "ttc<3", "gap<10"):
        out[c] = (int(Region.from_constraints([c], lane_width=model.lane_width_)
                      .contains(x).sum()), n_b)
    return out


def _brute(brute: dict[str, tuple[int, int]], region: str) -> tuple[float, float]:
    """Brute-force P(A | B) and the half-width of its own 95 % interval."""
    k, n_b = brute[region]
    p = k / n_b
    return p, 1.96 * math.sqrt(p * (1 - p) / n_b)


def _check_inside(ss: SampleSet, constraints: list[str]) -> None:
    p = ss.params[list(PARAM_NAMES)].to_numpy()
    assert np.isfinite(p).all()
    assert ss.region.contains(p).all()
    assert np.isfinite(ss.log_density).all()
    d = derive(p, lane_width=ss.region.lane_width)
    for c in constraints:
        name, val = c.split("<")
        assert (d[name] < float(val)).all()
        np.testing.assert_array_equal(ss.derived[name].to_numpy(), d[name])


# ---------------------------------------------------------------- same distribution


@pytest.fixture(scope="module")
def rejection_set(model: CutInGMM) -> SampleSet:
    return sample(model, MODERATE, 1200, seed=1, method="rejection", use_envelope=False)


def _same_distribution(a_set: SampleSet, b_set: SampleSet) -> None:
    ess = b_set.diagnostics["ess"]
    for name in PARAM_NAMES:
        a = a_set.params[name].to_numpy()
        b = b_set.params[name].to_numpy()
        # two-sample KS per marginal (8 tests, each at 0.001)
        assert stats.ks_2samp(a, b).pvalue > 1e-3, name
        # means within their Monte-Carlo error (MCMC error from its effective sample size)
        se = math.sqrt(a.var() / a.size + b.var() / ess)
        assert abs(a.mean() - b.mean()) < 4 * se, name


@pytest.mark.slow
def test_mcmc_and_rejection_give_the_same_distribution(model: CutInGMM,
                                                       rejection_set: SampleSet) -> None:
    mc = sample(model, MODERATE, 1200, seed=2, method="mcmc")
    _check_inside(mc, MODERATE)
    assert mc.method == "mcmc" and mc.diagnostics["converged"]
    _same_distribution(rejection_set, mc)


@pytest.mark.slow
def test_mcmc_without_envelope_on_a_smooth_model() -> None:
    """DE moves + the defensive fitted proposal, no envelope (a kinematic constraint).

    The model has no needle component (no exact p_a3 = 0 rows): see docs/sampler.md on why
    DE moves mix badly across a needle.
    """
    smooth = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=0, no_pulse_share=0.0))
    region = ["thw<0.4"]
    rej = sample(smooth, region, 1200, seed=1, method="rejection")
    assert rej.diagnostics["envelope"] is None
    mc = sample(smooth, region, 1200, seed=2, method=MCMCSampler(max_steps=6000))
    assert mc.diagnostics["independence_proposal"]["kind"] == "defensive-gaussian-mixture"
    p = mc.params[list(PARAM_NAMES)].to_numpy()
    assert mc.region.contains(p).all()
    _same_distribution(rej, mc)


def test_rejection_with_and_without_envelope_agree(model: CutInGMM,
                                                   rejection_set: SampleSet) -> None:
    env = sample(model, MODERATE, 1200, seed=3, method="rejection")
    assert env.diagnostics["envelope"]["source"] == "ttc<8"
    _check_inside(env, MODERATE)
    for name in PARAM_NAMES:
        assert stats.ks_2samp(rejection_set.params[name], env.params[name]).pvalue > 1e-3


def test_rejection_samples_are_the_truncated_model(model: CutInGMM) -> None:
    """Rejection samples vs brute-force draws of the model kept inside the region."""
    ss = sample(model, ["gap<10"], 2000, seed=4, method="rejection")
    x = model.params_matrix(model.sample(200_000, np.random.default_rng(77)))
    ref = x[Region.from_constraints(["gap<10"], lane_width=model.lane_width_).contains(x)]
    for j, name in enumerate(PARAM_NAMES):
        assert stats.ks_2samp(ss.params[name], ref[:, j]).pvalue > 1e-3, name


# ---------------------------------------------------------------- P(A)


@pytest.mark.slow
@pytest.mark.parametrize("region", ["ttc<8", "gap<10"])
@pytest.mark.parametrize("use_envelope", [True, False])
def test_p_region_against_brute_force(model: CutInGMM, brute: dict[str, tuple[int, int]],
                                      region: str, use_envelope: bool) -> None:
    ss = sample(model, [region], 300, seed=5, method="rejection", use_envelope=use_envelope)
    p_bf, bf_half = _brute(brute, region)
    pr = ss.p_region
    assert pr.method == ("envelope" if use_envelope else "mc")
    assert pr.ci_low <= pr.estimate <= pr.ci_high
    assert pr.ci_low - bf_half <= p_bf <= pr.ci_high + bf_half, (pr, p_bf)
    assert pr.rel_halfwidth < 0.2
    assert ss.exposure_weights.sum() == pytest.approx(pr.estimate, rel=1e-12)


@pytest.mark.slow
def test_importance_sampling_against_brute_force(model: CutInGMM,
                                                 brute: dict[str, tuple[int, int]]) -> None:
    est = PRegionEstimator(mc_min_hits=10**9)  # force the defensive-mixture estimator
    ss = sample(model, ["ttc<3"], 400, seed=6, method="mcmc", estimator=est)
    pr = ss.p_region
    assert pr.method == "is"
    p_bf, bf_half = _brute(brute, "ttc<3")
    assert pr.ci_low - bf_half <= p_bf <= pr.ci_high + bf_half, (pr, p_bf)
    assert pr.rel_halfwidth < 0.25


def test_estimate_p_region_alone(model: CutInGMM, brute: dict[str, tuple[int, int]]) -> None:
    pr = estimate_p_region(model, ["gap<10"], seed=8)
    p_bf, bf_half = _brute(brute, "gap<10")
    assert pr.ci_low - bf_half <= p_bf <= pr.ci_high + bf_half


def test_envelope_mass_and_draws(model: CutInGMM) -> None:
    region = Region.from_constraints(["dv>2"], lane_width=model.lane_width_)
    env = find_envelope(model, region)
    assert env is not None and env.source == "dv>2"
    # hand formula: P(dv > 2) = sum_k w_k (1 - Phi((z2 - mu_k) / sd_k)) in z-space
    j = model.features_.index("dv")
    tr = model.transforms_[j]
    z2 = (2.0 - tr.loc) / tr.scale
    exact = sum(w * stats.norm.sf((z2 - m[j]) / math.sqrt(c[j, j]))
                for w, m, c in zip(model.weights_, model.means_, model.covariances_,
                                   strict=True))
    assert env.mass == pytest.approx(exact, rel=1e-10)
    z = env.sample_z(model, 20_000, np.random.default_rng(0))
    assert env.contains(z).all()
    ref = model.sample_z(200_000, np.random.default_rng(1))
    ref = ref[ref[:, j] > z2]
    for d in range(model.n_features):
        assert stats.ks_2samp(z[:, d], ref[:, d]).pvalue > 1e-3


def test_ttc_envelope_contains_the_region(model: CutInGMM) -> None:
    region = Region.from_constraints(["ttc<2"], lane_width=model.lane_width_)
    env = find_envelope(model, region)
    assert env is not None and env.source == "ttc<2"
    z = model.sample_z(300_000, np.random.default_rng(3))
    inside = region.contains(model.params_matrix(model.from_z(z)))
    assert inside.sum() > 20
    assert env.contains(z[inside]).all()
    assert env.contains(z).mean() < 0.05  # and it is tight


# ---------------------------------------------------------------- diagnostics, auto


@pytest.mark.slow
def test_mcmc_diagnostics(model: CutInGMM) -> None:
    ss = sample(model, MODERATE, 300, seed=9, method="mcmc")
    d = ss.diagnostics
    assert len(d["acceptance_fraction"]) == d["n_walkers"] == 64
    assert 0 < d["acceptance_min"] <= d["acceptance_mean"] < 1
    assert len(d["tau"]) == 8 and all(t >= 1 for t in d["tau"])
    assert d["burn_in"] == math.ceil(2 * d["tau_max"])
    assert d["thin"] == max(1, math.ceil(d["tau_max"]))
    assert d["n_steps"] >= 30 * d["tau_max"]
    assert d["ess"] <= 300 and d["ess_chain_min"] > 0
    assert d["independence_proposal"]["kind"] == "envelope"


def test_tau_of_an_ar1_process() -> None:
    # AR(1) with phi: integrated autocorrelation time (1 + phi) / (1 - phi) = 3 for 0.5
    rng = np.random.default_rng(0)
    phi, n_t, n_w = 0.5, 4000, 32
    x = np.zeros((n_t, n_w, 1))
    e = rng.standard_normal((n_t, n_w))
    for t in range(1, n_t):
        x[t, :, 0] = phi * x[t - 1, :, 0] + e[t]
    assert integrated_time(x)[0] == pytest.approx(3.0, rel=0.1)
    x[:, 3, 0] = 1.0  # a stuck walker is ignored, not a division by zero
    assert integrated_time(x)[0] == pytest.approx(3.0, rel=0.1)


def test_auto_cost_rule() -> None:
    auto = AutoSampler(cost_ratio=50.0, tau_guess=30.0, burn_guess=600.0)
    # rejection cost n / p; MCMC cost 50 * (n * 30 + 64 * 600)
    common = Pilot(n_draws=1000, hits=np.zeros((100, 8)))  # p = 0.1: 1e4 << 1.6e6
    rare = Pilot(n_draws=10**7, hits=np.zeros((100, 8)))  # p = 1e-5: 1e8 >> 1.6e6
    assert auto.choose(1000, common).name == "rejection"
    assert auto.choose(1000, rare).name == "mcmc"
    # fewer pilot hits than MCMC walkers (64): subset simulation (issue 12); subset-is
    # for criticality regions
    assert auto.choose(1000, Pilot(n_draws=10**7, hits=np.zeros((63, 8)))).name == "subset"
    assert auto.choose(1000, Pilot(n_draws=10, hits=np.zeros((0, 8)))).name == "subset"
    assert auto.choose(1000, Pilot(n_draws=10, hits=np.zeros((0, 8))),
                       costly=True).name == "subset-is"


def test_auto_picks_rejection_on_moderate_region(model: CutInGMM) -> None:
    ss = sample(model, MODERATE, 200, seed=10, method="auto")
    assert ss.requested == "auto" and ss.method == "rejection"
    assert ss.diagnostics["auto"]["chosen"] == "rejection"


# ---------------------------------------------------------------- determinism, JSON


@pytest.mark.slow
@pytest.mark.parametrize("method", ["rejection", "mcmc", "auto"])
def test_same_seed_same_samples(model: CutInGMM, method: str) -> None:
    a = sample(model, MODERATE, 150, seed=11, method=method)
    b = sample(model, MODERATE, 150, seed=11, method=method)
    np.testing.assert_array_equal(a.params.to_numpy(), b.params.to_numpy())
    assert a.p_region == b.p_region
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    c = sample(model, MODERATE, 150, seed=12, method=method)
    assert not np.array_equal(a.params.to_numpy(), c.params.to_numpy())


def test_sample_set_json(model: CutInGMM) -> None:
    ss = sample(model, ["gap<10"], 50, seed=13)
    d = json.loads(json.dumps(ss.to_dict(), allow_nan=False))
    assert d["n"] == 50 and d["seed"] == 13
    assert d["constraints"] == [{"name": "gap", "op": "<", "value": 10.0}]
    assert set(d["params"]) == set(PARAM_NAMES) and len(d["params"]["gap"]) == 50
    assert set(d["p_region"]) >= {"estimate", "ci_low", "ci_high", "method", "confidence"}
    assert len(d["exposure_weights"]) == 50
    assert d["sampler_settings"]["sampler"]["name"] == "auto"
    back = SampleSet.from_dict(d)
    np.testing.assert_array_equal(back.params.to_numpy(), ss.params.to_numpy())
    assert back.p_region == ss.p_region and back.region == ss.region
    # ttc may be infinite (not closing): it becomes null in JSON
    assert all(v is None or v > 0 for v in d["derived"]["ttc"])
    scen = ss.scenario(0)
    assert scen.params == ss.params_dict(0) and scen.seed == 13
    assert scen.provenance["sample_index"] == 0


# ---------------------------------------------------------------- empty regions, errors


def test_empty_region_ends_with_an_error(model: CutInGMM) -> None:
    est = PRegionEstimator(pilot_max=1 << 16, search_draws=1 << 14)
    with pytest.raises(EmptyRegionError, match=r"looks empty.*envelope gap<5.*P\(A and B\) <"
                       ) as info:
        sample(model, ["gap<5", "gap>6"], 10, seed=1, estimator=est)
    assert info.value.n_hits == 0 and info.value.n_draws == (1 << 16) + 3 * (1 << 14)
    assert 0 < info.value.p_upper < 1e-3
    # without the envelope the bound is on plain model draws
    with pytest.raises(EmptyRegionError, match=r"none of 65536 model draws"):
        sample(model, ["gap<5", "gap>6"], 10, seed=1, estimator=est, use_envelope=False)


def test_practically_empty_region(model: CutInGMM) -> None:
    with pytest.raises(EmptyRegionError, match="practically empty"):
        sample(model, ["gap<10"], 10, seed=1, estimator=PRegionEstimator(min_p=0.5))


def test_rejection_budget_is_bounded(model: CutInGMM) -> None:
    from sampler.methods.samplers import RejectionSampler

    with pytest.raises(EmptyRegionError, match="use --sampler mcmc"):
        sample(model, ["ttc<3"], 5000, seed=1, use_envelope=False,
               method=RejectionSampler(max_draws=200_000))


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [({"n": 0}, "n: expected"), ({"seed": -1}, "seed"), ({"method": "gibbs"}, "valid: auto"),
     ({"constraints": ["speed<3"]}, "valid names")],
)
def test_bad_arguments(model: CutInGMM, kwargs: dict[str, object], fragment: str) -> None:
    args: dict[str, object] = {"constraints": MODERATE, "n": 10, "seed": 1}
    args.update(kwargs)
    with pytest.raises(SamplerError, match=fragment):
        sample(model, **args)  # type: ignore[arg-type]
