"""``btn_bound`` never lies below the simulated ``btn``, is tight enough to matter, and
ruling rows out with it changes no region's rows (``sampler.region.btn_bound``)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sampler.region.constraints as constraints_mod
from datasets.cutin_model import PARAM_NAMES
from riskcore.criticality.record import CriticalitySettings
from sampler.methods.problem import Problem
from sampler.model.gmm import CutInGMM
from sampler.region.btn_bound import a_req_bound, btn_bound
from sampler.region.constraints import Region, implied_bounds, parse_constraint
from sampler.region.criticality import criticality_quantities

LW = 3.75
DECEL_MAX = CriticalitySettings().decel_max


@pytest.fixture(scope="module")
def tno() -> CutInGMM:
    from datasets import default_parameter_table

    return CutInGMM(random_state=0).fit(default_parameter_table(), source="embedded")


def _vector(**kw: float) -> np.ndarray:
    base = {"p_y1": 0.04, "p_t": 2.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0, "p_v0": 25.0,
            "dv": 0.0, "gap": 20.0}
    base.update(kw)
    return np.array([[base[k] for k in PARAM_NAMES]])


def _check(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    btn = criticality_quantities(x, LW, with_ttr=False)["btn"]
    bound = btn_bound(x, LW)
    known = ~np.isnan(btn)  # NaN: not a buildable cut-in (the bound is +inf there)
    assert np.all(bound[known] >= btn[known]), np.flatnonzero(bound[known] < btn[known])
    for stop_at in (0.15, 0.4, 1.0):  # the cheaper bound below the limit: still a bound
        b2 = btn_bound(x, LW, stop_at=stop_at)
        assert np.all(b2[known] >= btn[known])
    return btn, bound


def test_by_hand() -> None:
    """Two cases worked out by hand."""
    # the cutter is 2 m/s faster and does not brake: the gap only opens, nothing is needed
    assert btn_bound(_vector(dv=-2.0), LW)[0] == 0.0
    # constant speeds, 8 m/s closing on a gap of 40 m: with braking at the crossing plus
    # the reaction time, (dv)^2 / (2 (gap - dv t_r)) = 64 / (2 * 34) = 0.94 m/s^2 (the
    # bound brakes a little later: t_p comes ~0.9 s before the crossing, so the simulated
    # driver needs less)
    x = _vector(dv=8.0, gap=40.0)
    a = a_req_bound(x, LW)[0]
    a_true = criticality_quantities(x, LW, with_ttr=False)["a_req"][0]
    assert a_true <= a <= 64 / (2 * (40 - 8 * 0.78 - 0.1))
    assert a == pytest.approx(a_true, rel=0.1)


@pytest.mark.slow
def test_never_below_btn_on_model_draws(tno: CutInGMM) -> None:
    """20,000 model draws and 20,000 draws of its ttc<3 envelope (where btn > 0.15 is
    common): the bound is never below btn, and it passes at most 1.5x the rows that
    reach each limit (measured ~1.0-1.3x)."""
    rng = np.random.default_rng(7)
    bounds = Region.from_constraints([], lane_width=LW)
    x = tno.params_matrix(tno.from_z(tno.sample_z(20_000, rng)))
    _check(x[bounds.in_bounds(x)])
    problem = Problem(tno, Region.from_constraints(["ttc<3"], lane_width=LW))
    xe = problem.params(problem.draw_z(20_000, rng))
    btn, bound = _check(xe[problem.region.contains(xe)])
    for limit in (0.15, 0.3):
        reach = int((btn > limit).sum())
        assert reach > 50
        assert (bound >= limit).sum() <= 1.5 * reach


@settings(max_examples=150, deadline=None)
@given(p_y1=st.floats(0.01, 0.12), p_t=st.floats(1.0, 4.0), p_a1=st.floats(-6.0, 3.0),
       p_a2=st.floats(-3.0, 8.0), p_a3=st.floats(0.0, 6.0), p_v0=st.floats(5.0, 40.0),
       dv=st.floats(-10.0, 15.0), gap=st.floats(0.5, 80.0), left=st.booleans())
def test_never_below_btn_for_any_vector(p_y1: float, p_t: float, p_a1: float, p_a2: float,
                                        p_a3: float, p_v0: float, dv: float, gap: float,
                                        left: bool) -> None:
    x = _vector(p_y1=p_y1 if left else -p_y1, p_t=p_t, p_a1=p_a1, p_a2=p_a2, p_a3=p_a3,
                p_v0=p_v0, dv=dv, gap=gap)
    _check(x)


def test_regions_keep_their_rows_and_simulate_fewer(
        tno: CutInGMM, monkeypatch: pytest.MonkeyPatch) -> None:
    """``btn > 0.3`` and ``a_req >= 2.3`` imply ``btn_bound >= 0.3``: the rows inside are
    those whose simulated btn passes, and only the rows whose bound reaches the limit are
    simulated."""
    assert implied_bounds([parse_constraint("btn>0.3"), parse_constraint("a_req>=2.3"),
                           parse_constraint("btn<0.9"), parse_constraint("ttc<3")]) == (
        parse_constraint("btn_bound>=0.3"),
        parse_constraint(f"btn_bound>={2.3 / DECEL_MAX!r}"))
    problem = Problem(tno, Region.from_constraints(["ttc<3"], lane_width=LW))
    x = problem.params(problem.draw_z(20_000, np.random.default_rng(3)))
    x = x[problem.region.contains(x)]
    btn = criticality_quantities(x, LW, with_ttr=False)["btn"]
    rows: list[int] = []
    real = constraints_mod.criticality_quantities

    def counted(params: np.ndarray, *args: object, **kwargs: object) -> dict[str, np.ndarray]:
        rows.append(params.shape[0])
        return real(params, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(constraints_mod, "criticality_quantities", counted)
    for text, want in (("btn>0.3", btn > 0.3), ("a_req>=2.3", btn * DECEL_MAX >= 2.3)):
        rows.clear()
        inside = Region.from_constraints(["ttc<3", text], lane_width=LW).contains(x)
        assert np.array_equal(inside, want)
        assert 0 < sum(rows) < 0.2 * x.shape[0]
    rows.clear()
    Region.from_constraints(["ttc<3", "btn<0.3"], lane_width=LW).contains(x)
    assert sum(rows) == x.shape[0]  # an upper limit implies nothing: every row simulated


@pytest.mark.slow
def test_auto_after_a_plain_pilot_keeps_its_estimate_and_avoids_mcmc(tno: CutInGMM) -> None:
    """A criticality region whose extended pilot was a plain run: more samples than its
    hits come from rejection (cheap behind ``btn_bound``) while n / p_hat draws stay
    within ``max_draws``, else from subset-is; never from MCMC (whose chains ran for
    more than 15 minutes in ``btn > 0.4``). P(A) stays the plain run's own estimate."""
    from sampler.methods.problem import Pilot
    from sampler.methods.samplers import AutoSampler
    from sampler.sampling import sample

    auto = AutoSampler()
    pilot = Pilot(n_draws=10_000_000, hits=np.zeros((80, 8)), plain=True)
    assert auto.choose(100, pilot, costly=True).name == "rejection"
    assert auto.choose(1000, pilot, costly=True).name == "subset-is"  # 1.25e8 draws
    assert auto.choose(80, pilot, costly=True).name == "rejection"  # the hits suffice
    ss = sample(tno, ["btn>0.15"], 300, seed=3)
    pilot_d = ss.diagnostics["pilot"]
    assert pilot_d["plain"] and pilot_d["n_hits"] < 300
    assert ss.method == "rejection" and len(ss) == 300
    assert (ss.derived["btn_bound"] >= 0.15).all()
    # the plain run's estimate, not one over the draws rejection added after it
    assert ss.p_region.n_draws == pilot_d["n_draws"]
    assert ss.p_region.n_hits == pilot_d["n_hits"]
    assert ss.p_region.method == "mc"
