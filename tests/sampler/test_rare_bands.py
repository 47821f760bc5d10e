"""subset-is and ``auto`` on thin regions (``2.9 < ttc < 3`` bands and a criticality
region with no kinematic constraint), against brute force computed here; the levels'
stall and convergence rules, the pilot's budgets and the split estimate by hand. Split
from tests/sampler/test_rare.py so that the suite's two workers (``--dist loadfile``)
share its long statistical tests."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy import stats

from datasets.embedded import default_parameter_table
from sampler.methods.probability import PRegionEstimator
from sampler.methods.problem import Problem
from sampler.methods.rare import (
    StrataBudget,
    rare_probability,
    stratified_importance,
)
from sampler.methods.strata import make_strata
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region
from sampler.sampling import sample
from tests.sampler.test_rare import _threshold
from tests.sampler.test_subset import _two_component


@pytest.fixture(scope="module")
def tno() -> CutInGMM:
    return CutInGMM(k_range=(1, 6), n_report_samples=500).fit(default_parameter_table())


# ------------------------------------------------------- thin regions: no silent drops


THIN_BAND = ["ttc<3", "ttc>2.9", "btn>0.4"]


def _band_brute_force(tno: CutInGMM, cons: list[str], n_ref: int, seed: int
                      ) -> tuple[float, int]:
    """(P(A and B), hits) of a ``2.9 < ttc < 3`` band region from ``n_ref`` exact draws of
    the model restricted to the ``ttc<3`` envelope (in blocks of 10^6), only the band's
    rows simulated. The physical bounds (row by row, and costly: their kinematic checks)
    are asked of the band's rows only, ~6 % of the draws: the same rows as asking all."""
    from sampler.region.constraints import derive

    region = Region.from_constraints(cons, lane_width=tno.lane_width_)
    problem = Problem(tno, region)
    assert problem.envelope is not None
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(n_ref // 1_000_000):
        x = problem.params(problem.draw_z(1_000_000, rng))
        ttc = derive(x, ["ttc"], lane_width=tno.lane_width_)["ttc"]
        band = x[(ttc > 2.9) & (ttc < 3)]
        band = band[region.in_bounds(band)]
        hits += int(region.contains(band).sum())
    return problem.envelope.mass * hits / n_ref, hits


@pytest.fixture(scope="module")
def thin_band_ref(tno: CutInGMM) -> tuple[float, int, int]:
    """Brute force of ``THIN_BAND``: (P(A and B), hits, envelope draws); 2,000,000 exact
    draws of the model restricted to the ``ttc<3`` envelope, only the band's rows
    simulated."""
    p_ref, hits = _band_brute_force(tno, THIN_BAND, 2_000_000, 17)
    assert hits > 50
    return p_ref, hits, 2_000_000


@pytest.fixture(scope="module")
def thin_band_sample(tno: CutInGMM) -> Any:
    """``sample(tno, THIN_BAND, 5, seed=1)`` with the default estimator: read by the two
    tests below (drawn once; neither changes it)."""
    return sample(tno, THIN_BAND, 5, seed=1)


@pytest.mark.slow
def test_thin_band_is_not_dropped(tno: CutInGMM, thin_band_ref: tuple[float, int, int]
                                  ) -> None:
    """``2.9 < ttc < 3 & btn > 0.4``: a thin band, where the levels' chains barely move.
    Before, a stratum holding nearly all of P(A) could end with too few distinct points
    (or levels that never converged) and was counted 0: seeds 4 and 5 gave 6.5e-12 and
    2.9e-11 with CoVs of 0.17 and 0.11 against the brute-force 1.06e-7. Now such a
    stratum's levels are re-run with more points; the estimates are no longer orders of
    magnitude off a brute force computed here (envelope draws, only the band's rows
    simulated). They are still biased low in such a band (0.47 and 0.75 of it for these
    seeds; docs/sampler.md), which is why ``auto`` estimates it by plain Monte Carlo
    (next test): the bound here is 0.25."""
    p_ref = thin_band_ref[0]
    for seed in (4, 5):
        r = rare_probability(tno, THIN_BAND, seed)
        assert 0.25 * p_ref < r.probability < 2.0 * p_ref


@pytest.mark.slow
def test_thin_band_auto_is_plain_and_exact(tno: CutInGMM,
                                           thin_band_ref: tuple[float, int, int],
                                           thin_band_sample: Any) -> None:
    """In the band, P(btn > 0.4 | band) is ~1e-3: the pilot of ``auto`` goes on (about 10^5
    simulations, within ``exact_sims``): a probe of 20 hits sizes a plain run for
    ``mc_min_hits`` hits on average, and P(A) is its exact estimate (method ``envelope``)
    instead of subset-is's, which was 0.85 of the brute force on average over 20 seeds with
    0.86 spread and 12 of 20 intervals covering it. The estimate agrees with the brute force
    within 3 combined standard errors, for three seeds, and ``sample`` gives the same P(A)
    as ``estimate_p_region``."""
    from sampler.sampling import estimate_p_region

    p_ref, hits_ref, _ = thin_band_ref
    # seed 1 with a progress callback (its stages are read below); ``sample`` runs the
    # same estimate without one
    heard: list[tuple[str, int, int]] = []
    estimates = {}
    for seed in (1, 2, 3):
        p = estimate_p_region(tno, THIN_BAND, seed,
                              progress=(lambda *a: heard.append(a)) if seed == 1 else None)
        estimates[seed] = p
        assert p.method == "envelope"
        assert p.n_hits >= 50  # a plain run sized for 100 hits on average
        se = math.hypot(p.p_joint / math.sqrt(p.n_hits), p_ref / math.sqrt(hits_ref))
        assert abs(p.p_joint - p_ref) < 3 * se
    ss = thin_band_sample
    assert ss.method == "rejection"
    p1 = estimates[1]
    assert ss.p_region.p_joint == p1.p_joint
    # the progress the catalogue status shows: the pilot's stages with their counts, which
    # do not change the estimate
    stages = [h[0] for h in heard]
    assert stages.index("pilot") < stages.index("pilot (plain Monte Carlo, probe)") \
        < stages.index("pilot (plain Monte Carlo)")
    plain = [(d, t) for name, d, t in heard if name == "pilot (plain Monte Carlo)"]
    assert plain[-1][0] == plain[-1][1] == ss.diagnostics["pilot"]["n_draws"]
    assert [d for d, _ in plain] == sorted(d for d, _ in plain)
    pilot = ss.diagnostics["pilot"]
    # the plain run simulated only the draws whose btn_bound reaches 0.4
    assert pilot["plain"] and pilot["probe_draws"] > 0
    assert 0 < pilot["n_simulated"] < 0.01 * (pilot["n_draws"] + pilot["probe_draws"])
    # the estimate is the plain run's alone, not the probe's draws too
    assert ss.p_region.n_draws == pilot["n_draws"] and ss.p_region.n_hits == pilot["n_hits"]


@pytest.mark.slow
def test_pilot_is_not_extended_beyond_its_budget(tno: CutInGMM, thin_band_sample: Any
                                                 ) -> None:
    """The extended pilot's two budgets. Draws: ``ttc<3 & btn>=1`` holds ~7e-6 of its
    envelope; after the pilot's 8,192 draws without a hit, the one-sided 90 % upper bound
    of the rate per draw, 2.3 / 8,192, projects ~3.6e5 draws for 100 hits, beyond an
    ``exact_draws`` of 2^16: no draw is added and subset-is estimates it. Simulations:
    the thin band (P(btn > 0.4 | band) ~ 1e-3) needs ~100 simulations for 100 hits once
    ``btn_bound`` rules out the rest, beyond a budget of 10, within the default."""


    cons = ["ttc<3", "btn>=1"]
    a = sample(tno, cons, 5, seed=3, estimator=PRegionEstimator(exact_draws=1 << 16))
    assert a.method == "subset-is"
    assert a.diagnostics["pilot"]["n_draws"] == 8192
    assert not a.diagnostics["pilot"]["plain"]
    small = sample(tno, THIN_BAND, 5, seed=1,
                   estimator=PRegionEstimator(exact_sims=10, exact_sims_thin=10))
    assert small.method == "subset-is"
    thin = thin_band_sample
    assert thin.method == "rejection"
    tp = thin.diagnostics["pilot"]
    # the bound leaves about one draw in 10^3 of the band's envelope to simulate
    assert 0 < tp["n_simulated"] < 0.01 * (tp["n_draws"] + tp["probe_draws"])


@pytest.mark.slow
def test_deep_thin_band_auto_is_plain_and_exact(tno: CutInGMM) -> None:
    """``2.9 < ttc < 3 & btn > 0.5``: P(btn > 0.5 | band) ~ 7e-5, beyond ``exact_sims``
    but the band is thin, so ``auto`` spends up to ``exact_sims_thin`` (2e6) simulations
    on plain Monte Carlo (~25 s). Subset-is gave 0.12-7.1 of the brute force over 10
    seeds (3 of them 0: a stratum cut as "empty" after its levels stalled; now refused
    as stalled and re-run). Checked against a brute force computed here: 12·10^6
    envelope draws, the band's rows simulated (~50 hits), within 3 combined standard
    errors."""
    from sampler.sampling import estimate_p_region

    cons = ["ttc<3", "ttc>2.9", "btn>0.5"]
    p_ref, hits = _band_brute_force(tno, cons, 12_000_000, 23)
    assert hits > 20
    p = estimate_p_region(tno, cons, 100)
    assert p.method == "envelope" and p.n_hits >= 50
    se = math.hypot(p.p_joint / math.sqrt(p.n_hits), p_ref / math.sqrt(hits))
    assert abs(p.p_joint - p_ref) < 3 * se


def test_stalled_levels_are_not_read_as_empty() -> None:
    """Thresholds repeated exactly for ``STALL_LEVELS`` levels mean the chains did not
    move; by hand on threshold lists, and on a limit state flat at 1 except a half-space
    (z0 > 12, never met): the p0-quantile is 1 at every level, so the levels stall; the
    EmptyRegionError says that its bound is not reliable and carries the threshold
    (``stalled``), which stratified subset-is reads as "retry with more points"."""
    from sampler import EmptyRegionError
    from sampler.methods.subset import STALL_LEVELS, _stalled, subset_simulation

    assert STALL_LEVELS == 3
    assert _stalled([1e6, 0.3, 0.2, 0.15, 0.15, 0.15]) == 0.15
    assert _stalled([1e6, 0.3, 0.3, 0.2, 0.2, 0.1]) is None  # runs of two
    assert _stalled([1e6, 1e6, 0.5]) is None  # the first level is plain Monte Carlo
    assert _stalled([0.4, 0.3, 0.2, 0.1, -0.1]) is None

    model = _two_component()

    def g(z: np.ndarray) -> np.ndarray:
        return np.where(z[:, 0] > 12.0, -1.0, 1.0)

    with pytest.raises(EmptyRegionError, match="stalled") as info:
        subset_simulation(model, g, 1, n_per_level=500)
    assert info.value.stalled == 1.0
    # a region the levels reach without stalling carries no such note
    with pytest.raises(EmptyRegionError) as ok:
        subset_simulation(model, lambda z: np.asarray(50.0 - z[:, 0]), 1, n_per_level=500,
                          min_probability=1e-6)
    assert ok.value.stalled is None and "stalled" not in str(ok.value)


def test_rare_estimate_below_the_pilots_exact_bound_is_overruled(tno: CutInGMM) -> None:
    """``contradicts``: 20 exact hits in 10^6 plain draws prove P(A and B) > 8.96e-6 at
    99.9 % (Poisson approximation: the 0.001 quantile of chi-square with 40 degrees of
    freedom, 17.92, halved: 8.96 events). A subset-is result at 5e-6 with CoV 0.1 (upper
    end 5e-6 x exp(1.96 x 0.0998) = 6.1e-6) is replaced by the pilot's plain estimate;
    one at 9e-6 (upper end 1.09e-5) is kept."""
    from types import SimpleNamespace

    from sampler.methods.problem import Pilot

    est = PRegionEstimator()
    problem = Problem(tno, Region.from_constraints(["btn>0.3"], lane_width=tno.lane_width_),
                      use_envelope=False)
    pilot = Pilot(n_draws=1_000_000, hits=np.zeros((20, tno.n_features)), n_simulated=700_000)
    bounds = (0.7, 0.69, 0.71)
    z = np.zeros((50, tno.n_features))
    low = SimpleNamespace(probability=5e-6, cov_upper=0.1, n_evaluations=9000, z=z,
                          method="subset-is")
    out = est.from_subset(problem, low, bounds, pilot)
    assert out.method == "mc" and out.n_hits == 20
    assert out.p_joint == pytest.approx(2e-5)
    assert out.ci_low * 0.71 == pytest.approx(stats.beta.ppf(0.025, 20, 1_000_000 - 19))
    ok = SimpleNamespace(probability=9e-6, cov_upper=0.1, n_evaluations=9000, z=z,
                         method="subset-is")
    assert est.from_subset(problem, ok, bounds, pilot).method == "subset-is"
    assert est.from_subset(problem, low, bounds).method == "subset-is"  # no pilot
    no_hit = Pilot(n_draws=1_000_000, hits=np.zeros((0, tno.n_features)))
    assert not est.contradicts(problem, est.from_subset(problem, low, bounds), no_hit)


def test_unconverged_stratum_is_retried_then_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    """A stratum whose levels met the region but did not converge is re-run with
    ``THIN_RETRY`` times the points per level; when that fails too, the run refuses with
    ``LevelsNotConvergedError`` naming the stratum instead of counting it 0."""
    import sampler.methods.rare as rare
    from sampler import LevelsNotConvergedError

    model = _two_component()
    a = np.zeros(model.n_features)
    a[0] = 1.0
    b = _threshold(model, a, 1e-5)

    def g(z: np.ndarray) -> np.ndarray:
        return np.asarray(b - z @ a, dtype=np.float64)

    calls: list[int] = []
    failures = {"left": 1}
    real = rare.subset_simulation

    def flaky(*args: object, n_per_level: int, **kw: object) -> object:
        calls.append(n_per_level)
        if failures["left"] > 0:
            failures["left"] -= 1
            raise LevelsNotConvergedError("levels stuck (test)", n_draws=7, n_hits=3)
        return real(*args, n_per_level=n_per_level, **kw)  # type: ignore[arg-type]

    strata = make_strata(model)[:1]  # one stratum: its first levels fail once
    monkeypatch.setattr(rare, "subset_simulation", flaky)
    r = stratified_importance(model, g, 0, strata=strata, budget=StrataBudget(n_probe=0))
    assert calls == [1000, rare.THIN_RETRY * 1000]
    assert r.probability > 0 and r.proposal["strata"][0]["n_is"] > 0
    calls.clear()
    failures["left"] = 2  # the retry fails too
    with pytest.raises(LevelsNotConvergedError, match=r"component 0.*also with 4000 points"):
        stratified_importance(model, g, 0, strata=strata, budget=StrataBudget(n_probe=0))


def test_auto_takes_the_pilots_hits_when_they_suffice() -> None:
    """A thin band's extended pilot holds ~100 exact hits from ~2.4e7 draws: for 20
    samples they are the samples (rejection, nothing more to draw); by the cost rule alone
    (20 / p_hat = 4.7e6 rejection draws against ~1e6 for MCMC) it chose MCMC, which took
    150 s of simulated chains on ``2.9 < ttc < 3 & btn > 0.5``. For 200 samples the cost
    rule still decides."""
    from sampler.methods.problem import Pilot
    from sampler.methods.samplers import AutoSampler

    pilot = Pilot(n_draws=24_000_000, hits=np.zeros((102, 8)))
    auto = AutoSampler()
    assert auto.choose(20, pilot, costly=True).name == "rejection"
    assert auto.choose(102, pilot, costly=True).name == "rejection"
    assert auto.choose(200, pilot, costly=True).name == "mcmc"


def test_combine_sums_disjoint_parts_by_hand() -> None:
    """``PRegionEstimator.combine``: P(A and B) = 3e-5 + 1e-5 = 4e-5; standard errors
    0.1 * 3e-5 (the part's CoV) and, without a CoV, from the interval
    (2e-5 - 0) / (2 * 1.959964) / 1e-5 * 1e-5 = 0.5102e-5; CoV = sqrt(0.3^2 + 0.5102^2)e-5
    / 4e-5 = 0.14797; log-normal interval 4e-5 exp(-+1.959964 sqrt(log(1 + 0.14797^2)))
    divided by P(B)'s upper / lower end."""
    from sampler.methods.probability import PRegion, PRegionEstimator

    def part(p: float, lo: float, hi: float, cov: float | None) -> PRegion:
        return PRegion(estimate=p / 0.5, ci_low=lo / 0.5, ci_high=hi / 0.5, confidence=0.95,
                       method="x", n_draws=10, n_hits=3, p_bounds=0.5,
                       p_bounds_ci=(0.4, 0.6), p_joint=p, cov=cov)

    a = part(3e-5, 2.5e-5, 3.6e-5, 0.1)  # its CoV is used, not its interval
    b = part(1e-5, 0.0, 2e-5, None)
    out = PRegionEstimator().combine([a, b], (0.5, 0.45, 0.55))
    z = 1.959963984540054
    se_b = (2e-5 / 0.5) / (2 * z * 2e-5) * 1e-5  # the interval's relative half-width x p
    cov = math.hypot(0.1 * 3e-5, se_b) / 4e-5
    assert se_b == pytest.approx(0.5102e-5, rel=1e-4)
    assert out.method == "split" and out.p_joint == pytest.approx(4e-5)
    assert out.estimate == pytest.approx(4e-5 / 0.5)
    assert out.cov == pytest.approx(cov) and cov == pytest.approx(0.14797, rel=1e-4)
    s = math.sqrt(math.log1p(cov**2))
    assert out.ci_low == pytest.approx(4e-5 * math.exp(-z * s) / 0.55)
    assert out.ci_high == pytest.approx(4e-5 * math.exp(z * s) / 0.45)
    assert (out.n_draws, out.n_hits) == (20, 6)


@pytest.mark.slow
def test_standalone_criticality_region_is_split_at_the_envelope(tno: CutInGMM) -> None:
    """``btn > 0.15`` has no kinematic constraint and the pilot finds too few hits: ``auto``
    estimates its part inside ``ttc<3`` (plain Monte Carlo in the envelope) and the rest
    (subset-is) apart and sums them. (Its P(A) ~ 1e-3 is within the extended pilot's plain
    budget by default, so the test turns that off: ``exact_sims`` 0, the path of rarer
    regions such as ``btn > 0.3``, whose brute force would take minutes.) Against a brute
    force of 2·10^6 plain model draws made here (about 1,900 hits), for four seeds: at least
    three within 2 combined standard errors, none beyond 4 (eight seeds gave 0.90-1.08 of
    the 10^7-draw reference of bench_rare). ``sample`` reports the same P(A), and a
    catalogue chunk's known P(A) is not re-estimated. With the default budget the plain
    run reaches it (``btn_bound``): within 3 combined standard errors, for two seeds."""
    from sampler.sampling import estimate_p_region

    def est() -> PRegionEstimator:
        return PRegionEstimator(exact_sims=0, exact_sims_thin=0)

    from sampler.region.criticality import criticality_quantities

    # the brute force simulates every draw inside the bounds (Region.contains would skip
    # those whose btn_bound stays below 0.15: not independent of the bound under test)
    bounds = Region.from_constraints([], lane_width=tno.lane_width_)
    rng = np.random.default_rng(99)
    hits, n_ref = 0, 2_000_000
    for _ in range(8):
        x = tno.params_matrix(tno.from_z(tno.sample_z(n_ref // 8, rng)))
        x = x[bounds.in_bounds(x)]
        hits += int((criticality_quantities(x, tno.lane_width_, with_ttr=False)["btn"]
                     > 0.15).sum())
    p_ref = hits / n_ref
    assert hits > 1000
    # the default: plain Monte Carlo, which simulates only the draws whose btn_bound
    # reaches 0.15 (``sampler.region.btn_bound``), exact and unbiased
    for seed in (1, 2):
        d = sample(tno, ["btn>0.15"], 5, seed=seed)
        p = d.p_region
        assert p.method == "mc" and d.diagnostics["pilot"]["plain"]
        pilot = d.diagnostics["pilot"]
        assert pilot["n_simulated"] < 0.01 * (pilot["n_draws"] + pilot["probe_draws"])
        se = math.hypot(p.p_joint / math.sqrt(p.n_hits), p_ref / math.sqrt(hits))
        assert abs(p.p_joint - p_ref) < 3 * se
    z = []
    for seed in (1, 2, 3, 4):
        p = estimate_p_region(tno, ["btn>0.15"], seed, estimator=est())
        assert p.method == "split" and p.cov is not None
        z.append((p.p_joint - p_ref) / math.hypot(p.cov * p.p_joint, p_ref / math.sqrt(hits)))
    assert sum(abs(v) < 2 for v in z) >= 3 and max(abs(v) for v in z) < 4, z
    ss = sample(tno, ["btn>0.15"], 5, seed=4, estimator=est())  # p is seed 4's
    assert ss.p_region.p_joint == p.p_joint and ss.p_region.method == "split"
    parts = ss.diagnostics["split"]["parts"]
    assert parts[0]["method"] in ("envelope", "mc") and parts[1]["method"] == "subset-is"
    assert sum(q["p_joint"] for q in parts) == pytest.approx(p.p_joint)
    known = sample(tno, ["btn>0.15"], 5, seed=5, known_region=p)
    assert known.p_region == p and "split" not in known.diagnostics


def test_an_empty_part_counts_with_its_bound_and_stalled_ones_raise(
        tno: CutInGMM, monkeypatch: pytest.MonkeyPatch) -> None:
    """``AutoSampler.split_estimate``: a part whose estimate ends "empty" adds 0 with its
    upper bound as the error; a stalled one (unreliable bound) or all parts empty raise."""
    from sampler import EmptyRegionError
    from sampler.methods.probability import PRegion, PRegionEstimator
    from sampler.methods.problem import Problem, Run
    from sampler.methods.samplers import AutoSampler, split_parts

    inside = PRegion(estimate=2e-5, ci_low=1.6e-5, ci_high=2.4e-5, confidence=0.95,
                     method="envelope", n_draws=1000, n_hits=100, p_bounds=0.5,
                     p_bounds_ci=(0.5, 0.5), p_joint=1e-5, cov=0.1)
    region = Region.from_constraints(["btn>0.3"], lane_width=tno.lane_width_).bind(tno)
    parts = split_parts(region)
    assert parts is not None and [p.describe() for p in parts] == [
        "btn>0.3 & ttc<3 & physical bounds", "btn>0.3 & ttc>=3 & physical bounds"]

    def fake(outcomes: list[object]) -> object:
        def estimate(*args: object, **kwargs: object) -> PRegion:
            out = outcomes.pop(0)
            if isinstance(out, Exception):
                raise out
            assert isinstance(out, PRegion)
            return out
        return estimate

    run = Run(Problem(tno, region), np.random.default_rng(0), PRegionEstimator(),
              (0.5, 0.5, 0.5), seed=1)
    empty = EmptyRegionError("empty", n_draws=50, p_upper=3e-6)
    monkeypatch.setattr(AutoSampler, "estimate_region", fake([inside, empty]))
    p, info = AutoSampler().split_estimate(run, parts)
    z = 1.959963984540054
    # 1e-5 with error 0.1e-5, plus 0 with error 3e-6 / z
    assert p.p_joint == pytest.approx(1e-5)
    assert p.cov == pytest.approx(math.hypot(1e-6, 3e-6 / z) / 1e-5)
    assert [q["method"] for q in info] == ["envelope", "empty"]
    stalled = EmptyRegionError("stalled", p_upper=3e-6, stalled=0.15)
    monkeypatch.setattr(AutoSampler, "estimate_region", fake([inside, stalled]))
    with pytest.raises(EmptyRegionError, match="stalled"):
        AutoSampler().split_estimate(run, parts)
    monkeypatch.setattr(AutoSampler, "estimate_region", fake([empty, empty]))
    with pytest.raises(EmptyRegionError):
        AutoSampler().split_estimate(run, parts)
    # not split: a ttr_true constraint, a kinematic envelope already, no criticality
    for cons in (["ttr_true<2"], ["btn>0.3", "ttr_true<3"], ["ttc<3", "btn>0.3"],
                 ["gap<5", "btn>0.3"], ["v_ego>30"]):
        r = Region.from_constraints(cons, lane_width=tno.lane_width_).bind(tno)
        assert split_parts(r) is None, cons
