"""Subset simulation: against closed-form P(A), against brute force on the real model,
determinism, the time bound, empty regions, and ``auto``'s choice."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from datasets.embedded import default_parameter_table
from sampler import EmptyRegionError, SamplerError
from sampler.methods.probability import PRegionEstimator
from sampler.methods.samplers import AutoSampler, Pilot, make_sampler
from sampler.methods.subset import SubsetSampler, mixture_from_normal, subset_simulation
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region
from sampler.sampling import estimate_p_region, sample

REPS = 40


@pytest.fixture(scope="module")
def tno() -> CutInGMM:
    """The model of the real TNO cut-ins (embedded table)."""
    return CutInGMM(k_range=(1, 6), n_report_samples=500).fit(default_parameter_table())


def _two_component(d: int = 8) -> CutInGMM:
    """A hand-made mixture: weights 0.7 / 0.3, distinct means and covariances."""
    rng = np.random.default_rng(11)
    a = rng.standard_normal((d, d)) * 0.3
    cov1 = np.eye(d) + a @ a.T
    model = CutInGMM.from_dict({
        "format": "scengen.cutin-gmm/1",
        "features": [f"f{i}" for i in range(d)],
        "transforms": [{"feature": f"f{i}", "kind": "identity", "shift": 0.0, "loc": 0.0,
                        "scale": 1.0} for i in range(d)],
        "fixed": {name: 1.0 for name in ("p_v0", "p_a1", "p_a2", "p_a3", "p_t", "p_y1",
                                         "gap", "dv")},
        "weights": [0.7, 0.3],
        "means": [[0.0] * d, [1.5] + [-0.5] * (d - 1)],
        "covariances": [np.eye(d).tolist(), cov1.tolist()],
    })
    return model


def _halfspace_exact(model: CutInGMM, a: np.ndarray, b: float) -> float:
    """P(a.z >= b) under the mixture, in closed form."""
    return float(sum(w * stats.norm.sf((b - a @ mu) / math.sqrt(a @ s @ a))
                     for w, mu, s in zip(model.weights_, model.means_, model.covariances_,
                                         strict=True)))


def test_normal_map_gives_the_mixture() -> None:
    model = _two_component(3)
    u = np.random.default_rng(0).standard_normal((200_000, 4))
    z = mixture_from_normal(model, u)
    # first moment of the mixture, hand-computed: 0.7 * 0 + 0.3 * mean_2
    np.testing.assert_allclose(z.mean(axis=0), [0.45, -0.15, -0.15], atol=0.01)
    a = np.array([1.0, 0.0, 0.0])
    assert np.mean(z[:, 0] >= 2.0) == pytest.approx(_halfspace_exact(model, a, 2.0), abs=3e-3)


@pytest.mark.slow
@pytest.mark.parametrize("p_true", [1e-4, 1e-5, 1e-6, 1e-7])
def test_halfspace_under_one_component_matches_closed_form(p_true: float) -> None:
    """z_0 >= b under the second component only (the first has weight ~0 there):
    inside 2 CoV of the exact P(A) in >= 90 % of seeded repetitions, and unbiased."""
    model = _two_component()
    a = np.zeros(model.n_features)
    a[0] = 1.0
    # threshold in the second component's tail: solve the closed form for b
    from scipy.optimize import brentq

    b = brentq(lambda t: _halfspace_exact(model, a, t) - p_true, 0.0, 40.0)
    share_first = 0.7 * stats.norm.sf(b) / p_true
    assert share_first < 1e-3  # the region lies under one Gaussian component

    def g(z: np.ndarray) -> np.ndarray:
        return np.asarray(b - z[:, 0], dtype=np.float64)

    res = [subset_simulation(model, g, seed, n_per_level=2000) for seed in range(REPS)]
    est = np.array([r.probability for r in res])
    cov = np.array([r.cov_upper for r in res])
    inside = np.abs(est - p_true) <= 2.0 * cov * p_true
    assert inside.mean() >= 0.9
    # unbiased: the mean of the repetitions within 3 standard errors
    assert abs(est.mean() - p_true) <= 3.0 * est.std(ddof=1) / math.sqrt(REPS)
    # and cheaper than plain Monte Carlo for the same (measured) CoV
    cov_measured = est.std(ddof=1) / p_true
    naive = (1 - p_true) / (p_true * cov_measured**2)
    assert np.mean([r.n_evaluations for r in res]) < naive
    for r in res:
        assert (r.z[:, 0] >= b).all()  # the final level's samples lie inside A


@pytest.mark.slow
def test_real_model_against_brute_force(tno: CutInGMM) -> None:
    """ttc < 3 with the physical bounds on the TNO model: brute force over 2M draws."""
    region = Region.from_constraints(["ttc<3"], lane_width=tno.lane_width_)
    x = tno.params_matrix(tno.sample(2_000_000, np.random.default_rng(99)))
    k = int(region.contains(x).sum())
    p_ref = k / 2_000_000  # P(A and B), ~1500 hits: 2.6 % relative error
    assert k > 1000
    from sampler.methods.subset import region_limit_state

    est, cov = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        r = subset_simulation(tno, region_limit_state(tno, region, rng), seed,
                              n_per_level=2000)
        est.append(r.probability)
        cov.append(r.cov_upper)
    e, c = np.array(est), np.array(cov)
    assert np.mean(np.abs(e - p_ref) <= 2.0 * c * p_ref) >= 0.9
    assert abs(e.mean() - p_ref) <= 3.0 * e.std(ddof=1) / math.sqrt(len(e)) + 0.05 * p_ref


def test_sample_with_subset_is_deterministic_and_inside(tno: CutInGMM) -> None:
    a = sample(tno, ["ttc<1.5"], 300, seed=4, method="subset")
    b = sample(tno, ["ttc<1.5"], 300, seed=4, method="subset")
    assert a.method == "subset" and a.p_region.method == "subset"
    np.testing.assert_array_equal(a.params.to_numpy(), b.params.to_numpy())
    assert a.p_region == b.p_region
    assert len(a.params) == 300
    assert a.region.contains(a.params[list(a.params.columns[:8])].to_numpy()).all()
    assert (a.derived["ttc"] < 1.5).all()
    assert a.p_region.ci_low < a.p_region.estimate < a.p_region.ci_high
    assert a.p_region.cov is not None and a.p_region.cov > 0
    assert a.diagnostics["subset"]["levels"] >= 2


def test_subset_p_region_agrees_with_envelope_estimate(tno: CutInGMM) -> None:
    """ttc < 1.5: the exact envelope estimator (tight interval) lies inside subset's."""
    ref = sample(tno, ["ttc<1.5"], 50, seed=1, method="rejection").p_region
    assert ref.method == "envelope" and ref.rel_halfwidth < 0.1
    sub = sample(tno, ["ttc<1.5"], 50, seed=1, method="subset").p_region
    assert sub.ci_low <= ref.estimate <= sub.ci_high


def test_time_bound_gives_a_clear_error() -> None:
    model = _two_component()
    with pytest.raises(SamplerError, match="max_seconds"):
        subset_simulation(model, lambda z: np.asarray(30.0 - z[:, 0]), 0, max_seconds=1e-9)


def test_unreachable_region_is_empty() -> None:
    model = _two_component()
    with pytest.raises(EmptyRegionError, match="min_probability") as info:
        subset_simulation(model, lambda z: np.asarray(60.0 - z[:, 0]), 0,
                          min_probability=1e-6)
    assert info.value.p_upper is not None and info.value.p_upper < 1e-5


def test_bad_settings_are_refused() -> None:
    model = _two_component()
    with pytest.raises(SamplerError, match="p0"):
        subset_simulation(model, lambda z: z[:, 0], 0, p0=0.7)
    with pytest.raises(SamplerError, match="n_per_level"):
        subset_simulation(model, lambda z: z[:, 0], 0, n_per_level=20)


def test_auto_picks_subset_when_the_pilot_finds_too_few_hits(tno: CutInGMM) -> None:
    auto = AutoSampler()
    d = tno.n_features
    few = Pilot(n_draws=1 << 20, hits=np.zeros((3, d)))
    assert auto.choose(100, few).name == "subset"
    assert auto.choose(100, few, costly=True).name == "subset-is"  # criticality regions
    assert auto.choose(100, Pilot(n_draws=1 << 14, hits=np.zeros((400, d)))).name == \
        "rejection"
    # a short pilot on a rare region: auto runs subset simulation
    est = PRegionEstimator(pilot_max=1 << 14)
    ss = sample(tno, ["ttc<1.5"], 100, seed=3, estimator=est, use_envelope=False)
    assert ss.method == "subset" and ss.diagnostics["auto"]["chosen"] == "subset"
    assert isinstance(make_sampler("subset"), SubsetSampler)


@pytest.mark.slow
def test_estimate_p_region_uses_subset_for_rare_regions(tno: CutInGMM) -> None:
    """thw < 0.1 (no half-space envelope, P ~ 4e-6): the 1M-draw pilot finds too few."""
    p = estimate_p_region(tno, ["thw<0.1"], seed=2)
    assert p.method == "subset"
    assert 0 < p.ci_low < p.estimate < p.ci_high < 1e-4
    assert p == estimate_p_region(tno, ["thw<0.1"], seed=2)


def test_empty_region_ends_in_bounded_work(tno: CutInGMM) -> None:
    """gap < 5 and gap > 6: g never reaches 0; the level cap ends it with EmptyRegionError."""
    with pytest.raises(EmptyRegionError, match="did not reach the region"):
        sample(tno, ["gap<5", "gap>6"], 10, seed=0, method="subset")


@pytest.mark.parametrize("op", ["<", "<=", ">", ">="])
def test_ttc_margin_sign_is_membership_by_hand(op: str) -> None:
    """``gap - c dv`` (``c dv - gap`` for > / >=): its sign is TTC membership for closing
    (dv > 0), standing (dv = 0) and opening (dv < 0) cut-ins, on both sides of the
    threshold and on it."""
    from datasets.cutin_model import ttc_from_gap_dv
    from sampler.methods.subset import ttc_margin
    from sampler.region.constraints import OPERATORS

    c = 2.0
    #            closing: ttc 1, 2 (threshold), 4 | standing | opening | gap <= 0
    gap = np.array([10.0, 20.0, 40.0, 10.0, 10.0, 0.0, -5.0, -5.0, -5.0])
    dv = np.array([10.0, 10.0, 10.0, 0.0, -3.0, 5.0, 5.0, 0.0, -1.0])
    ttc = np.array([1.0, 2.0, 4.0, math.inf, math.inf, 0.0, -1.0, math.inf, math.inf])
    np.testing.assert_array_equal(ttc_from_gap_dv(gap, dv), ttc)  # the hand values
    inside = OPERATORS[op](ttc, c)
    m = ttc_margin(gap, dv, op, c)
    assert np.isfinite(m).all()
    got = m < 0 if op in ("<", ">") else m <= 0
    np.testing.assert_array_equal(got, inside)
    # continuous in the closing part: the margin is gap - c dv there, by hand
    sgn = 1.0 if op in ("<", "<=") else -1.0
    np.testing.assert_allclose(m[:3], sgn * np.array([-10.0, 0.0, 20.0]))
    # the non-closing rows are not all one value (ttc is +inf on all of them)
    assert np.unique(m[3:5]).size == 2


@pytest.mark.parametrize("cons", [["ttc<2"], ["ttc>=2.5", "gap<30"], ["btn>0.15"],
                                  ["ttc<3", "btn>0.5"], ["ttr_true<2.8"],
                                  ["thw<1.5", "btn>0.2"], ["ttc<4", "btn>0.1", "btn<1"],
                                  ["ttc<5", "gap<40", "ttr_true<3", "btn>0.05"]])
def test_region_limit_state_is_the_region_and_not_flat(tno: CutInGMM,
                                                       cons: list[str]) -> None:
    """g <= 0 exactly on the region's rows; and g takes distinct values over the
    physical rows where the quantities themselves are flat (ttc +inf, btn 0, ttr_true
    +inf for every cut-in the constant-speed ego never reaches), so subset levels can
    shrink there."""
    from sampler.methods.subset import region_limit_state

    region = Region.from_constraints(cons, lane_width=tno.lane_width_)
    z = tno.sample_z(6000, np.random.default_rng(3))
    x = tno.params_matrix(tno.from_z(z))
    g = region_limit_state(tno, region, np.random.default_rng(0))(z)
    np.testing.assert_array_equal(g <= 0, region.contains(x))
    fin = g[np.isfinite(g)]
    assert fin.size == int(region.in_bounds(x).sum())  # finite on every physical row
    # ttr_true is a multiple of its scan step where finite: ties there, not in the flat part
    share = 0.7 if "ttr_true<2.8" in cons else 0.99
    assert np.unique(fin).size >= share * fin.size


@pytest.mark.parametrize("cons", [["ttc<3", "btn>0.3"], ["ttc<3", "btn>0.2", "btn<0.6"],
                                  ["ttc<3", "ttr_true<2.5", "btn>0.1"]])
def test_layered_limit_state_simulates_only_inside_the_kinematic_part(
        tno: CutInGMM, cons: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Kinematic and criticality constraints together: on draws of the ``ttc<3``
    envelope (38 % inside ``ttc<3``), ``g <= 0`` is exactly the region, every row outside
    ``ttc<3`` gets a value above every row inside it (the levels close in on the
    kinematic part first), and no row outside ``ttc<3`` is simulated, not even for the
    margins' scales (one criticality quantity) or for them (two: only model draws)."""
    import sampler.methods.subset as ss
    from sampler.methods.envelope import find_envelope
    from sampler.region.constraints import derive

    region = Region.from_constraints(cons, lane_width=tno.lane_width_)
    env = find_envelope(tno, region)
    assert env is not None
    z = env.sample_z(tno, 4000, np.random.default_rng(8))
    x = tno.params_matrix(tno.from_z(z))
    simulated: list[np.ndarray] = []
    original = ss.criticality_quantities

    def counted(params: np.ndarray, *args: object, **kwargs: object) -> object:
        simulated.append(np.asarray(params))
        return original(params, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(ss, "criticality_quantities", counted)
    g = ss.region_limit_state(tno, region, np.random.default_rng(0))
    n_scale_rows = sum(p.shape[0] for p in simulated)
    assert n_scale_rows == (2048 if len({c.name for c in region.constraints}) > 2 else 0)
    simulated.clear()
    values = g(z)
    np.testing.assert_array_equal(values <= 0, region.contains(x))
    ttc = derive(x, ["ttc"], lane_width=tno.lane_width_)["ttc"]
    kin = (ttc < 3) & region.in_bounds(x)
    assert 0.2 < kin.mean() < 0.6
    assert values[~kin & np.isfinite(values)].min() > values[kin].max()
    rows = np.concatenate(simulated)
    assert rows.shape[0] == int(kin.sum())  # exactly the rows inside ttc<3, once each
    assert (derive(rows, ["ttc"], lane_width=tno.lane_width_)["ttc"] < 3).all()
