"""sampler.campaign.band.lateral_band and its parts: the set ``0 < end_margin < c``.

The band (a thin interval of ``p_y1`` given the other parameters, from the small-angle
linearisation ``y_end = p_y1 J``) is checked against the kinematics' own ``end_margin``
(``sampler.region.constraints.derive``, a trapezoid rule on ``sin psi``), with the
linearisation's error bound; ``J`` against an adaptive quadrature; the parts' densities
as ``test_campaign_band`` checks the ``v_cut_min`` band part's.

The synthetic table's lane changes cover about 3.7 m, so the lane width here is 7 m:
its half, 3.5 m, lies in the bulk of the model and the band holds about a percent of it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from sampler import CutInGMM
from sampler.campaign.band import BandPart, fit_band_part, lateral_band, lateral_gain
from sampler.campaign.proposal import (
    DEFAULT_ENVELOPES,
    _envelope_parts,
    _rest_fit,
    build_proposal,
    lateral_band_parts,
)
from sampler.region.constraints import derive
from tests.sampler.factories import assert_band_density, synthetic_parameter_table

LANE = 7.0
C = 0.05
#: derive's trapezoid rule (512 intervals, pulse kinks between nodes) against the
#: band's Gauss-Legendre rule: an absolute allowance on the lateral displacement, m
QUAD_TOL = 1e-4


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


@pytest.fixture(scope="module")
def parts(model: CutInGMM) -> list[BandPart]:
    out = lateral_band_parts(model, C, LANE, seed=5, n=1 << 16)
    assert [p.name for p in out] == ["band:end_margin<0.05:left", "band:end_margin<0.05:right"]
    return out


def _cols(model: CutInGMM) -> tuple[int, int, int, int, int]:
    f = list(model.features_)
    return (f.index("p_t"), f.index("p_a1"), f.index("p_a2"), f.index("p_a3"),
            f.index("p_v0"))


def test_gain_is_the_linearised_displacement(model: CutInGMM) -> None:
    """J against scipy's adaptive quadrature of v(t) (p_t / pi)(1 - cos(pi t / p_t)),
    split at the pulse's ends; without a pulse J = p_v0 2 p_t^2 / pi."""
    rows = [  # p_t, p_a1, p_a2, p_a3, p_v0
        (2.5, 0.0, 0.0, 0.0, 25.0),
        (3.0, -2.0, -1.0, 10.0, 30.0),   # braking from before t0 to after the lane change
        (4.0, 1.5, 1.0, 2.0, 20.0),      # a pulse inside the lane change
        (1.5, -0.7, 2.5, 4.0, 18.0),     # starting inside, ending after
        (2.0, 3.0, 5.0, 1.0, 22.0),      # after the lane change: no effect
        (2.0, 1.0, 0.5, -0.05, 22.0),    # p_a3 < 0 (the model's tail): v constant
    ]
    x = np.zeros((len(rows), model.n_features))
    cols = _cols(model)
    for i, r in enumerate(rows):
        x[i, list(cols)] = r
    got = lateral_gain(x, cols)
    for i, (pt, a1, a2, a3, v0) in enumerate(rows):
        c0 = min(max(-a2, 0.0), a3)

        def f(t: float, pt: float = pt, a1: float = a1, a2: float = a2, a3: float = a3,
              v0: float = v0, c0: float = c0) -> float:
            v = v0 + a1 * (min(max(t - a2, 0.0), a3) - c0)
            return v * pt / math.pi * (1.0 - math.cos(math.pi * t / pt))

        pts = [t for t in (a2, a2 + a3) if 0 < t < 2 * pt]
        want = integrate.quad(f, 0.0, 2 * pt, points=pts or None, epsabs=1e-12,
                              epsrel=1e-12)[0]
        assert math.isclose(got[i], want, rel_tol=1e-9), (i, got[i], want)
    assert math.isclose(got[0], 25.0 * 2 * 2.5**2 / math.pi, rel_tol=1e-9)


@pytest.mark.parametrize("side", [1, -1])
def test_band_is_the_end_margin_set(model: CutInGMM, side: int) -> None:
    """On model draws, against derive's end_margin and cross_margin. ``sin u >= u - u^3 /
    6`` makes the true displacement at least ``1 - psi_max^2 / 6`` of the linearised one
    (v >= 0), so per row: a row on the band has ``-tol < end_margin < c + QUAD_TOL`` with
    ``tol = (lane / 2 + c) psi_max^2 / 6 + QUAD_TOL``; a physical row of this side with
    ``QUAD_TOL < cross_margin < c - tol`` is on it; a physical row with ``cross_margin``
    below ``-tol`` or above ``c + QUAD_TOL``, or of the other side, is not."""
    z = model.sample_z(200_000, np.random.default_rng(1))
    x = model.from_z(z)
    q = derive(model.params_matrix(x), ["end_margin", "cross_margin", "psi_max", "v_cut_min"],
               lane_width=LANE)
    e, cm, psi, vmin = (np.asarray(q[k]) for k in ("end_margin", "cross_margin", "psi_max",
                                                    "v_cut_min"))
    j = list(model.features_).index("p_y1")
    lo, hi = lateral_band(model, C, side, LANE)(z)
    on = (z[:, j] > lo) & (z[:, j] < hi)
    phys = vmin > 0
    same = np.sign(x[:, j]) == side
    tol = (LANE / 2 + C) * psi**2 / 6 + QUAD_TOL
    assert on.sum() > 300  # ~0.3 % of the draws per side
    assert np.all(same[on])
    assert np.all((e[on & phys] > -tol[on & phys]) & (e[on & phys] < C + QUAD_TOL))
    clear_in = phys & same & (cm > QUAD_TOL) & (cm < C - tol)
    clear_out = phys & ((cm < -tol) | (cm > C + QUAD_TOL) | ~same)
    assert clear_in.sum() > 0.8 * on.sum()
    assert np.all(on[clear_in])
    assert not np.any(on[clear_out])
    # measured 0.954 on each side (the rest: within the linearisation's error of 0)
    inset = (e > 0) & (e < C)
    assert inset[on].mean() > 0.93


def test_band_on_a_log_coordinate_has_no_negative_side(model: CutInGMM) -> None:
    """With p_y1 log-transformed (only p_y1 > 0 representable) the right-hand band is
    empty everywhere and the left-hand one is the identity model's in p_y1 units."""
    data = model.to_dict()
    log_model = CutInGMM.from_dict(data)
    j = list(model.features_).index("p_y1")
    tr = model.transforms_[j]
    log_tr = type(tr)(tr.feature, "log", 0.0, -3.0, 0.5)
    log_model.transforms_ = [log_tr if i == j else t for i, t in enumerate(model.transforms_)]
    x = model.from_z(model.sample_z(2000, np.random.default_rng(2)))
    x[:, j] = np.abs(x[:, j])
    zl = log_model.to_z(x)
    lo, hi = lateral_band(log_model, C, -1, LANE)(zl)
    assert np.all(lo == -np.inf) and np.all(hi == -np.inf)
    lo_l, hi_l = lateral_band(log_model, C, 1, LANE)(zl)
    lo_i, hi_i = lateral_band(model, C, 1, LANE)(model.to_z(x))
    to_x = log_model.transforms_[j].inverse
    fin = np.isfinite(lo_i)
    assert fin.mean() > 0.9
    assert np.allclose(to_x(lo_l[fin]), tr.inverse(lo_i[fin]), rtol=1e-12)
    assert np.allclose(to_x(hi_l[fin]), tr.inverse(hi_i[fin]), rtol=1e-12)


@pytest.mark.parametrize("k", [0, 1])
def test_lateral_part_is_a_density_on_its_band(model: CutInGMM, parts: list[BandPart],
                                               k: int) -> None:
    """As the v_cut_min band part's test: with r = (p + q) / 2 the mean of q / r is 1;
    the weights p / q on the part's draws average to the band's mass (brute force); the
    draws lie on the band and mostly in the set by derive; deterministic."""
    part = parts[k]
    rng = np.random.default_rng(4)
    n = 60_000
    zq = part.draw(n, rng)
    lo, hi = part.band(zq)
    zj = zq[:, part.law.j]
    full = hi > lo
    assert full.mean() > 0.99
    assert np.all((zj[full] >= lo[full]) & (zj[full] <= hi[full]))
    assert_band_density(model, part, zq, n, rng)
    e = np.asarray(derive(model.params_matrix(model.from_z(zq[:5000])), ["end_margin"],
                          lane_width=LANE)["end_margin"])
    assert ((e > 0) & (e < C)).mean() > 0.93  # measured 0.956 and 0.964 on 20,000
    again = lateral_band_parts(model, C, LANE, seed=5, n=1 << 16)[k]
    assert np.array_equal(again.draw(50, np.random.default_rng(9)),
                          part.draw(50, np.random.default_rng(9)))


def test_envelope_parts_make_two_bands_once(model: CutInGMM) -> None:
    """``end_margin<c`` (or ``<=``) among the envelopes gives the two lateral band parts
    on p_y1, memoised; the default envelopes include ``end_margin<0.03``."""
    assert "end_margin<0.03" in DEFAULT_ENVELOPES
    first = _envelope_parts(model, ["end_margin<0.05"], LANE, None)
    assert [p.name for p in first] == ["band:end_margin<0.05:left",
                                       "band:end_margin<0.05:right"]
    j = list(model.features_).index("p_y1")
    assert all(isinstance(p, BandPart) and p.law.j == j for p in first)
    again = _envelope_parts(model, ["end_margin<0.05"], LANE, None)
    assert all(a is b for a, b in zip(first, again, strict=True))
    le = _envelope_parts(model, ["end_margin<=0.05"], LANE, None)
    assert [p.name for p in le] == ["band:end_margin<=0.05:left",
                                    "band:end_margin<=0.05:right"]
    prop = build_proposal(model, region=None, lane_width=LANE,
                          envelopes=(*DEFAULT_ENVELOPES, "end_margin<0.05"))
    names = [p.name for p in prop.parts]
    assert "band:end_margin<0.05:left" in names and "band:end_margin<0.05:right" in names


def test_thinning_is_checked(model: CutInGMM) -> None:
    j = list(model.features_).index("p_y1")
    with pytest.raises(ValueError, match="thin"):
        fit_band_part(model, j, lateral_band(model, C, 1, LANE), _rest_fit, "x",
                      thin="smallest")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="side"):
        lateral_band(model, C, 0, LANE)


def test_bands_with_collided_runs_split_the_refits_share(model: CutInGMM,
                                                         parts: list[BandPart]) -> None:
    """In the final stage each band with at least 2 d collided runs on it gets a refit and a
    kernel part; with both lateral bands hit they split ``BAND_HITS_SHARE`` equally (with
    one share each, as before the split, the shares summed past 1 and the proposal raised),
    and the whole mixture still has mean weight 1."""
    from sampler.campaign.proposal import BAND_HITS_SHARE, BAND_KERNEL_SHARE, build_ce_proposal

    rng = np.random.default_rng(11)
    d = model.n_features
    hits = np.concatenate([p.draw(2 * d + 4, rng) for p in parts])
    prop = build_ce_proposal(model, region=None, lane_width=LANE,
                             elite=(hits, np.ones(hits.shape[0])), level=0.0,
                             rng=np.random.default_rng(12), envelopes=("end_margin<0.05",))
    shares = {x["part"]: x["share"] for x in prop.describe()}
    for side in ("left", "right"):
        refit = shares[f"ce:band:end_margin<0.05:{side}-hits"]
        kern = shares[f"ce:band:end_margin<0.05:{side}-kernels"]
        assert math.isclose(kern, BAND_KERNEL_SHARE / 2, rel_tol=1e-12)
        assert math.isclose(refit + kern, BAND_HITS_SHARE / 2, rel_tol=1e-12)
    assert all(s > 0 for s in shares.values())
    assert math.isclose(sum(shares.values()), 1.0, rel_tol=1e-12)
    z, _ = prop.draw(100_000, np.random.default_rng(13))
    w = np.exp(model.log_density_z(z) - prop.log_q(z))
    se = w.std(ddof=1) / math.sqrt(w.size)
    assert abs(w.mean() - 1.0) <= 4 * se


def test_band_step_narrows_only_the_default_slow_cutter_set() -> None:
    """``campaign_envelopes``: with ``band_step`` the default list's ``v_cut_min<3``
    becomes ``v_cut_min<1.5`` and nothing else changes; without it, or for a list of the
    caller's own, the list is kept as given."""
    from sampler.campaign.proposal import BAND_STEP_ENVELOPES, campaign_envelopes

    assert campaign_envelopes(DEFAULT_ENVELOPES, False) == DEFAULT_ENVELOPES
    got = campaign_envelopes(list(DEFAULT_ENVELOPES), True)
    assert got == BAND_STEP_ENVELOPES
    assert [e for e in got if e not in DEFAULT_ENVELOPES] == ["v_cut_min<1.5"]
    assert [e for e in DEFAULT_ENVELOPES if e not in got] == ["v_cut_min<3"]
    assert len(got) == len(DEFAULT_ENVELOPES)
    own = ("ttc<2", "v_cut_min<3")
    assert campaign_envelopes(own, True) == own
