"""sampler.campaign.band: the proposal part that lives on the band ``0 < v_cut_min < c``.

Checked three ways: a band worked out by hand from the pulse's kinematics; the model's
conditional law against the model's own joint density (an identity) and against brute
force (the band's mass); and the part's density integrating to 1 and its weights
averaging to the band's mass, by importance sampling with a tight standard error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from sampler import CutInGMM
from sampler.campaign.band import (
    BandPart,
    ConditionalLaw,
    _truncated_std_normal,
    v_cut_min_band,
)
from sampler.campaign.proposal import (
    BAND_HITS_SHARE,
    BAND_KERNEL_SHARE,
    BAND_LEVEL_ELITE,
    FINAL_SET_SHARE,
    BandPool,
    _band_level_elite,
    band_part,
    build_ce_proposal,
)
from sampler.region.kinematics import plateau_speeds
from tests.sampler.factories import assert_band_density, synthetic_parameter_table

#: ~0.15 % of the synthetic model's draws (as tests/sampler/test_campaign_ce.py)
C = 15.0


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


@pytest.fixture(scope="module")
def part(model: CutInGMM) -> BandPart:
    bp = band_part(model, C, seed=5, n=1 << 16)
    assert bp is not None
    return bp


def _col(model: CutInGMM, name: str) -> int:
    return list(model.features_).index(name)


def test_band_by_hand(model: CutInGMM) -> None:
    """A cutter braking at 2 m/s^2 for 10 s from 1 s before t0 (c0 = 1 s):
    before = v0 + 2, after = v0 + 2 - 20 = v0 - 18, so 0 < v_cut_min < 15 is
    18 < v0 < 33. A pulse that speeds the cutter up (a1 = +1 for 4 s, from t0):
    v_cut_min = v0, band 0 < v0 < 15."""
    x = np.zeros((2, model.n_features))
    for j, name in enumerate(model.features_):
        x[:, j] = {"p_y1": 3.0, "p_t": 4.0, "p_v0": 25.0, "dv": 2.0, "gap": 20.0}.get(
            name, 0.0)
    x[0, [_col(model, "p_a1"), _col(model, "p_a2"), _col(model, "p_a3")]] = [-2.0, -1.0, 10.0]
    x[1, [_col(model, "p_a1"), _col(model, "p_a2"), _col(model, "p_a3")]] = [1.0, 0.0, 4.0]
    z = model.to_z(x)
    lo, hi = v_cut_min_band(model, C)(z)
    jv = _col(model, "p_v0")
    want = np.array([[18.0, 33.0], [0.0, 15.0]])
    for i in range(2):
        xi = np.repeat(x[i:i + 1], 2, axis=0)
        xi[:, jv] = want[i]
        z_want = model.to_z(xi)[:, jv]
        if want[i, 0] > 0:
            assert math.isclose(lo[i], z_want[0], rel_tol=1e-12, abs_tol=1e-12)
        else:  # v0 > 0 always (log transform): no lower end
            assert lo[i] == -math.inf
        assert math.isclose(hi[i], z_want[1], rel_tol=1e-12, abs_tol=1e-12)


def test_band_is_the_slow_set(model: CutInGMM) -> None:
    """On model draws, in the band iff 0 < v_cut_min < c by the kinematics' formula."""
    z = model.sample_z(200_000, np.random.default_rng(1))
    x = model.from_z(z)
    before, after = plateau_speeds(x[:, _col(model, "p_a1")], x[:, _col(model, "p_a2")],
                                   x[:, _col(model, "p_a3")], x[:, _col(model, "p_v0")])
    vmin = np.minimum(before, after)
    slow = (vmin > 0) & (vmin < C)
    lo, hi = v_cut_min_band(model, C)(z)
    zj = z[:, _col(model, "p_v0")]
    on = (zj > lo) & (zj < hi)
    assert slow.sum() > 50
    assert np.array_equal(on, slow)


def test_conditional_law_is_the_model(model: CutInGMM) -> None:
    """log p(z) = log p(z_rest) + log p(z_j | z_rest) to rounding, and the band's
    conditional mass F averaged over model draws is the band's mass (brute force)."""
    law = ConditionalLaw(model, _col(model, "p_v0"))
    rng = np.random.default_rng(2)
    z = model.sample_z(2000, rng)
    lc = law.log_pdf_j(z)
    assert np.allclose(model.log_density_z(z), law.last_log_marginal + lc, atol=1e-10)
    z = model.sample_z(200_000, rng)
    band = v_cut_min_band(model, C)
    lo, hi = band(z)
    log_f, _ = law.log_mass(z, lo, np.maximum(hi, lo))
    f = np.exp(log_f)
    zj = z[:, law.j]
    on = (zj > lo) & (zj < hi)
    # the same draws: E[1_band - F] = 0 with the variance of the difference
    d = on - f
    assert abs(d.mean()) <= 4 * d.std(ddof=1) / math.sqrt(d.size)
    assert on.mean() > 5e-4


@pytest.mark.parametrize("a, b", [(-1.0, 2.0), (3.0, 5.0), (-math.inf, -8.0), (9.0, math.inf),
                                  (-0.5, -0.4)])
def test_truncated_normal_follows_scipy(a: float, b: float) -> None:
    rng = np.random.default_rng(3)
    n = 20_000
    x = _truncated_std_normal(np.full(n, a), np.full(n, b), rng.random(n))
    assert np.all((x >= a) & (x <= b))
    ks = stats.kstest(x, stats.truncnorm(a, b).cdf)
    assert ks.pvalue > 1e-3


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-60, 60), width=st.floats(0.0, 50), u=st.floats(0, 1))
def test_truncated_normal_stays_inside_any_interval(a: float, width: float, u: float) -> None:
    """Finite and inside [a, b] for any interval, deep tails included."""
    x = _truncated_std_normal(np.array([a]), np.array([a + width]), np.array([u]))
    assert np.isfinite(x).all() and a <= x[0] <= a + width


def test_band_part_is_a_density_on_its_band(model: CutInGMM, part: BandPart) -> None:
    """With r = (p + q) / 2, drawn half from the model and half from the part, the mean
    of q / r is the integral of q, 1; the part's weights p / q on its own draws average
    to the band's mass (brute force); its draws all lie on the band,
    and it is deterministic."""
    rng = np.random.default_rng(4)
    n = 60_000
    zq = part.draw(n, rng)
    lo, hi = part.band(zq)
    zj = zq[:, part.law.j]
    full = hi > lo  # an empty band: p_v0 from the untruncated conditional
    assert full.mean() > 0.9
    assert np.all((zj[full] >= lo[full]) & (zj[full] <= hi[full]))
    assert_band_density(model, part, zq, n, rng)
    again = band_part(model, C, seed=5, n=1 << 16)
    assert again is not None
    assert np.array_equal(again.draw(50, np.random.default_rng(9)),
                          part.draw(50, np.random.default_rng(9)))


def test_final_stage_refits_the_band_to_its_collisions(model: CutInGMM) -> None:
    """At level 0 with enough elite rows on the band, the proposal gains the band part
    refitted to them and the band with kernels at them (together ``band_hits_share``,
    the kernels ``BAND_KERNEL_SHARE`` of it), the set share drops to the final one, and
    the whole mixture's weights still average to 1."""
    envs = (f"v_cut_min<{C:g}",)
    band = v_cut_min_band(model, C)
    z = model.sample_z(200_000, np.random.default_rng(7))
    lo, hi = band(z)
    zj = z[:, _col(model, "p_v0")]
    on = (zj > lo) & (zj < hi)
    # "collided" rows: the 60 band rows with the smallest gaps (a corner of the band)
    z_on = z[on]
    z_e = z_on[np.argsort(z_on[:, _col(model, "gap")])[:60]]
    assert z_e.shape[0] == 60
    prop = build_ce_proposal(model, region=None, lane_width=model.lane_width_,
                             elite=(z_e, np.ones(60)), level=0.0,
                             rng=np.random.default_rng(8), envelopes=envs)
    shares = {d["part"]: d["share"] for d in prop.describe()}
    assert math.isclose(shares[f"band:v_cut_min<{C:g}"], FINAL_SET_SHARE, rel_tol=1e-12)
    assert math.isclose(shares[f"ce:band:v_cut_min<{C:g}-hits"],
                        BAND_HITS_SHARE - BAND_KERNEL_SHARE, rel_tol=1e-12)
    assert math.isclose(shares[f"ce:band:v_cut_min<{C:g}-kernels"], BAND_KERNEL_SHARE,
                        rel_tol=1e-12)
    assert math.isclose(sum(shares.values()), 1.0, rel_tol=1e-12)
    with pytest.raises(ValueError, match="lower alpha"):
        build_ce_proposal(model, region=None, lane_width=model.lane_width_,
                          elite=(z_e, np.ones(60)), level=0.0,
                          rng=np.random.default_rng(8), envelopes=envs, alpha=0.45)
    zq, _ = prop.draw(40_000, np.random.default_rng(9))
    w = np.exp(model.log_density_z(zq) - prop.log_q(zq))
    assert np.isfinite(w).all() and w.max() <= 1 / 0.1 + 1e-9
    se = w.std(ddof=1) / math.sqrt(w.size)
    assert abs(w.mean() - 1.0) <= 4 * se
    # the refitted part puts far more of its draws on the collided rows' neighbourhood
    hits_part = next(p for p in prop.parts if p.name.endswith("-hits"))
    assert isinstance(hits_part, BandPart)
    zh = hits_part.draw(5000, np.random.default_rng(10))
    lo_h, hi_h = band(zh)
    zj_h = zh[:, _col(model, "p_v0")]
    full = hi_h > lo_h  # an empty band: p_v0 from the untruncated conditional
    assert full.mean() > 0.9
    assert np.all((zj_h[full] >= lo_h[full]) & (zj_h[full] <= hi_h[full]))
    # its draws sit where the collided rows do: in the gap coordinate that picked them,
    # far closer to them than the base band's draws
    base = next(p for p in prop.parts if p.name == f"band:v_cut_min<{C:g}")
    assert isinstance(base, BandPart)
    zb = base.draw(5000, np.random.default_rng(11))
    centre = z_e.mean(axis=0)
    jg = _col(model, "gap")
    assert (np.median(np.abs(zh[:, jg] - centre[jg]))
            < 0.5 * np.median(np.abs(zb[:, jg] - centre[jg])))


def test_band_kernels_keep_mass_on_a_group_the_refit_misses(model: CutInGMM) -> None:
    """Collided rows on the band in two groups, one of 3 rows far from the other 57: the
    refit (at most 2 components, BIC on the effective size) may merge or drop the small
    group, the kernels may not. Each kernel is a Student-t(5) at a resampled row with the
    scale Silverman's rule gives (checked by hand on the mixture's fields); the kernel
    part's density at the small group is at least that of one kernel at its own centre
    times its share of the centres; and the band part made of them draws there."""
    envs = (f"v_cut_min<{C:g}",)
    band = v_cut_min_band(model, C)
    z = model.sample_z(200_000, np.random.default_rng(7))
    lo, hi = band(z)
    zj = z[:, _col(model, "p_v0")]
    z_on = z[(zj > lo) & (zj < hi)]
    jg = _col(model, "gap")
    order = np.argsort(z_on[:, jg])
    z_e = np.concatenate([z_on[order[:57]], z_on[order[-3:]]])  # smallest and largest gaps
    prop = build_ce_proposal(model, region=None, lane_width=model.lane_width_,
                             elite=(z_e, np.ones(60)), level=0.0,
                             rng=np.random.default_rng(8), envelopes=envs)
    kern = next(p for p in prop.parts if p.name.endswith("-kernels"))
    assert isinstance(kern, BandPart)
    g = kern.g
    rest = kern.law.rest
    d = rest.size
    m = g.weights.size
    assert m == 240 and np.allclose(g.weights, 1 / m) and g.nu == 5.0
    # the scale by hand: weighted covariance (equal weights, ddof 0) + 0.05 I, times h^2
    zr = z_e[:, rest]
    n_distinct = np.unique(np.round(zr, 12), axis=0).shape[0]
    h = (4 / (d + 2)) ** (1 / (d + 4)) * n_distinct ** (-1 / (d + 4)) * 1.3
    cov = np.cov(zr.T, bias=True) + 0.05 * np.eye(d)
    assert np.allclose(g.covs[0], h * h * cov) and np.allclose(g.covs, g.covs[0])
    # every centre is one of the rows
    assert all(np.any(np.all(np.isclose(c, zr), axis=1)) for c in g.means)
    small = zr[-3:]
    at_small = np.sum(np.all(np.isclose(g.means[:, None, :], small[None]), axis=2), axis=0)
    assert at_small.sum() >= 1  # 3 of 60 rows, 240 draws: P(none) = (57/60)^240 ~ 5e-6
    # the density against a slow reference: the mean of the 240 t pdfs (scipy)
    pts = np.concatenate([small, zr[:5], g.draw(20, np.random.default_rng(13))])
    ref = np.mean([stats.multivariate_t(loc=c, shape=g.covs[0], df=5.0).pdf(pts)
                   for c in g.means], axis=0)
    assert np.allclose(np.exp(g.log_q(pts)), ref, rtol=1e-9)
    # at the small group: at least its centres' share of one kernel's peak
    i = int(np.argmax(at_small))
    peak = stats.multivariate_t(loc=small[i], shape=g.covs[0], df=5.0).pdf(small[i])
    assert np.exp(g.log_q(small[i:i + 1]))[0] >= at_small[i] / m * peak


def _on_band(part: BandPart, z: np.ndarray) -> np.ndarray:
    lo, hi = part.band(z)
    zj = z[:, part.law.j]
    return np.asarray((zj >= lo) & (zj <= hi), dtype=bool)


def test_band_level_elite_against_brute_force(model: CutInGMM, part: BandPart) -> None:
    """The band's own elite is the ``size`` runs on the band with the lowest scores:
    checked against the band evaluated on every row (the function walks the rows by
    score in blocks), with non-finite scores never chosen; None until the band part drew
    ``min_drawn`` rows, and None when fewer than ``size`` runs lie on the band."""
    rng = np.random.default_rng(21)
    z = model.sample_z(30_000, rng)
    score = rng.standard_normal(z.shape[0])
    score[::7] = np.inf  # runs outside the region: never elite
    w = rng.uniform(0.5, 2.0, z.shape[0])
    pool = BandPool(z, w, score, {part.name: 500})
    on = _on_band(part, z) & np.isfinite(score)
    assert on.sum() > 40
    want = np.flatnonzero(on)[np.argsort(score[on], kind="stable")[:25]]
    got = _band_level_elite(part, pool, min_drawn=300, size=25, block=997)
    assert got is not None
    assert np.array_equal(got[0], z[want]) and np.array_equal(got[1], w[want])
    assert _band_level_elite(part, pool, min_drawn=501, size=25) is None
    assert _band_level_elite(part, pool, min_drawn=300, size=int(on.sum()) + 1) is None
    assert _band_level_elite(part, BandPool(z, w, score, {}), min_drawn=1, size=5) is None


def test_final_stage_without_band_collisions_follows_the_band_near_misses(
        model: CutInGMM) -> None:
    """At level 0 with no collided run on the band but a pool of runs so far, the band
    gets one part ``-level``: the band with ``g`` refitted to its lowest-score runs,
    with all of ``band_hits_share``; its draws stay on the band and sit where those runs
    do, and the whole mixture's weights still average to 1."""
    envs = (f"v_cut_min<{C:g}",)
    bp = band_part(model, C, seed=0, n=1 << 18)  # the proposal's own (memoised) part
    assert bp is not None
    rng = np.random.default_rng(31)
    z = model.sample_z(200_000, rng)
    on = _on_band(bp, z)
    jg = _col(model, "gap")
    score = np.where(on, z[:, jg], np.inf) + 10.0  # no run collided (score > 0)
    pool = BandPool(z, np.ones(z.shape[0]), score, {bp.name: 1000})
    # collided runs elsewhere only: far off the band
    z_hit = z[~on][:40]
    prop = build_ce_proposal(model, region=None, lane_width=model.lane_width_,
                             elite=(z_hit, np.ones(40)), level=0.0,
                             rng=np.random.default_rng(8), envelopes=envs, pool=pool)
    shares = {d["part"]: d["share"] for d in prop.describe()}
    name = f"ce:band:v_cut_min<{C:g}-level"
    assert math.isclose(shares[name], BAND_HITS_SHARE, rel_tol=1e-12)
    assert not any(n.endswith(("-hits", "-kernels")) for n in shares if n.startswith("ce:band"))
    zq, _ = prop.draw(40_000, np.random.default_rng(9))
    wq = np.exp(model.log_density_z(zq) - prop.log_q(zq))
    se = wq.std(ddof=1) / math.sqrt(wq.size)
    assert abs(wq.mean() - 1.0) <= 4 * se
    lev = next(p for p in prop.parts if p.name == name)
    assert isinstance(lev, BandPart)
    zl = lev.draw(5000, np.random.default_rng(10))
    lo, hi = lev.band(zl)
    full = hi > lo
    assert full.mean() > 0.9 and np.all(_on_band(lev, zl)[full])
    elite = z[on][np.argsort(z[on][:, jg])[:BAND_LEVEL_ELITE]]
    zb = bp.draw(5000, np.random.default_rng(11))
    centre = np.median(elite[:, jg])
    assert np.median(np.abs(zl[:, jg] - centre)) < 0.5 * np.median(np.abs(zb[:, jg] - centre))
