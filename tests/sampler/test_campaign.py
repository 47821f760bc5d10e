"""sampler.campaign: the importance-sampled collision probability of a system under test.

The stand-in runners have answers known without the code under test: a half-space in the
model's z-space has the mass sum_k w_k Phi((b - a mu_k) / sqrt(a' S_k a)) (computed here
with scipy from the model's own mixture), and the late-braking driver's outcomes follow from
two lines of kinematics worked out by hand below.
"""

from __future__ import annotations

import json
import math
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import pytest
from scipy import stats

from sampler import CutInGMM
from sampler.campaign import (
    ChunkResult,
    StandInRuns,
    evaluate,
    halfspace_runner,
    late_brake_runner,
)
from sampler.errors import SamplerError
from sampler.rates import Exposure
from tests.sampler.factories import synthetic_parameter_table


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


def _mass(model: CutInGMM, a: np.ndarray, b: float) -> float:
    """P(a.z <= b) under the model's mixture, by hand (scipy's normal CDF)."""
    total = 0.0
    for w, mu, cov in zip(model.weights_, model.means_, model.covariances_, strict=True):
        total += w * stats.norm.cdf((b - a @ mu) / math.sqrt(a @ cov @ a))
    return float(total)


def _rare_halfspace(model: CutInGMM, target: float) -> tuple[np.ndarray, float, float]:
    """A half-space along (small gap, large dv) with mass close to ``target``."""
    a = np.zeros(model.n_features)
    a[model.features_.index("gap")] = 1.0
    a[model.features_.index("dv")] = -0.7
    lo, hi = -15.0, 0.0
    for _ in range(60):  # bisection on b
        mid = 0.5 * (lo + hi)
        if _mass(model, a, mid) < target:
            lo = mid
        else:
            hi = mid
    return a, hi, _mass(model, a, hi)


def _assert_unbiased_and_covering(model: CutInGMM, runner: Any, p_true: float,
                                  **options: Any) -> list[dict[str, Any]]:
    """40 campaigns ``evaluate(model, runner, seed=s, physical_bounds=False,
    bootstrap=False, **options)``, s = 0 … 39, on a stand-in with the known probability
    ``p_true``: the mean of their estimates within 3 standard errors of it and within
    15 %, and the 95 % interval covering it in at least 34. Returns their summaries."""
    summaries = [evaluate(model, runner, seed=s, physical_bounds=False, bootstrap=False,
                          **options).summary() for s in range(40)]
    e = np.asarray([summ["p_collision"]["estimate"] for summ in summaries])
    covered = 0
    for summ in summaries:
        lo, hi = summ["p_collision"]["ci"]
        covered += int(lo is not None and lo <= p_true <= hi)
    se_mean = e.std(ddof=1) / math.sqrt(e.size)
    # unbiased: the mean of 40 independent estimates within 3 standard errors of P
    assert abs(e.mean() - p_true) <= 3 * se_mean
    assert abs(e.mean() / p_true - 1) < 0.15
    # the 95 % interval covers P in (nearly) 95 % of the campaigns
    assert covered >= 34
    return summaries


def test_unbiased_and_covering_on_a_closed_form_case(model: CutInGMM) -> None:
    a, b, p_true = _rare_halfspace(model, 3e-5)
    _assert_unbiased_and_covering(model, halfspace_runner(model, a, b), p_true, n=800,
                                  batch_size=400)


def test_stop_rule_reaches_the_relative_half_width(model: CutInGMM) -> None:
    a, b, p_true = _rare_halfspace(model, 1e-5)
    r = evaluate(model, halfspace_runner(model, a, b), seed=5, batch_size=500,
                 physical_bounds=False, bootstrap=False)
    s = r.summary()
    assert s["stop_reason"] == "rhw"
    assert s["p_collision"]["rhw"] <= 0.3 and s["collisions"] >= 10
    lo, hi = s["p_collision"]["ci"]
    assert lo < p_true < hi
    # far fewer runs than naive Monte Carlo would need for this standard error
    assert s["acceleration"] > 100
    assert s["runs"] % 500 == 0 and s["chunks"] == s["runs"] // 500


def test_same_seed_same_result_and_executor_changes_nothing(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 1e-4)
    runner = halfspace_runner(model, a, b)
    one = evaluate(model, runner, n=900, seed=2, batch_size=300, physical_bounds=False,
                   bootstrap=False, part_size=100)
    with ThreadPoolExecutor(2) as pool:
        two = evaluate(model, runner, n=900, seed=2, batch_size=300, physical_bounds=False,
                       bootstrap=False, part_size=100, executor=pool)
    assert json.dumps(one.summary()) == json.dumps(two.summary())
    for c1, c2 in zip(one.chunks, two.chunks, strict=True):
        assert np.array_equal(c1.z, c2.z) and np.array_equal(c1.seeds, c2.seeds)
    other = evaluate(model, runner, n=900, seed=3, batch_size=300, physical_bounds=False,
                     bootstrap=False)
    assert not np.array_equal(one.chunks[0].z, other.chunks[0].z)


class _Counting:
    def __init__(self, inner: object) -> None:
        self.inner = inner
        self.rows = 0
        self.name = getattr(inner, "name", "counting")

    def __call__(self, params: np.ndarray, seeds: np.ndarray) -> object:
        self.rows += params.shape[0]
        return self.inner(params, seeds)  # type: ignore[operator]


def test_resume_from_stored_chunks_is_byte_identical(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 3e-5)
    stored: list[str] = []
    first = evaluate(model, halfspace_runner(model, a, b), seed=11, batch_size=300,
                     physical_bounds=False, bootstrap=False,
                     on_chunk=lambda c: stored.append(json.dumps(c.to_dict())))
    assert len(stored) == len(first.chunks) >= 3
    # a crash after two chunks: resume from what the job had stored
    counting = _Counting(halfspace_runner(model, a, b))
    again = evaluate(model, counting, seed=11, batch_size=300, physical_bounds=False,
                     bootstrap=False, stored=[json.loads(t) for t in stored[:2]])
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(first.summary(),
                                                                     sort_keys=True)
    replayed_rows = sum(int(c.simulated.sum()) for c in first.chunks[:2])
    assert counting.rows == first.sut_runs - replayed_rows
    assert [r["weight"] for r in again.records()] == [r["weight"] for r in first.records()]


def test_a_stored_chunk_of_another_campaign_is_refused(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 1e-3)
    r = evaluate(model, halfspace_runner(model, a, b), n=200, seed=0, batch_size=200,
                 physical_bounds=False, bootstrap=False)
    with pytest.raises(SamplerError, match="stored"):
        evaluate(model, halfspace_runner(model, a, b), n=300, seed=0, batch_size=300,
                 physical_bounds=False, bootstrap=False, stored=[r.chunks[0]])


def test_chunk_round_trip_is_lossless() -> None:
    chunk = ChunkResult(
        index=3, params=np.array([[0.1, 2.0, -1.0, 0.5, 1.0, 20.0, 3.0, 1e-300]]),
        z=np.array([[1 / 3, -2.5, 0.0, 1e10, -1e-10, 7.0, np.pi, -0.0]]),
        seeds=np.array([2**64 - 1], dtype=np.uint64), part=np.array([2]),
        log_p=np.array([-20.123456789]), log_q=np.array([-18.1]),
        weights=np.array([math.exp(-2.023456789)]), simulated=np.array([True]),
        outcome={"collided": np.array([True]), "impact_speed": np.array([np.nan]),
                 "min_ttc": np.array([np.inf]), "vs_careful": np.array(["worse"])},
        proposal=[{"part": "model", "share": 0.15}])
    back = ChunkResult.from_dict(json.loads(json.dumps(chunk.to_dict())))
    for name in ("params", "z", "seeds", "part", "log_p", "log_q", "weights", "simulated"):
        assert np.array_equal(getattr(back, name), getattr(chunk, name), equal_nan=True), name
        assert getattr(back, name).tobytes() == getattr(chunk, name).tobytes(), name
    assert np.isnan(back.outcome["impact_speed"][0]) and back.outcome["min_ttc"][0] == np.inf
    assert back.outcome["vs_careful"].tolist() == ["worse"]
    assert back.index == 3 and back.proposal == chunk.proposal


def test_no_collision_gives_the_weighted_rule_of_three(model: CutInGMM) -> None:
    def never(params: np.ndarray, seeds: np.ndarray) -> StandInRuns:
        n = params.shape[0]
        return StandInRuns(np.zeros(n, dtype=bool), np.zeros(n), np.zeros(n, dtype=bool),
                           np.zeros(n, dtype=bool))

    r = evaluate(model, never, n=1000, seed=0, batch_size=500, physical_bounds=False,
                 bootstrap=False, alpha=0.2)
    s = r.summary()["p_collision"]
    assert s["estimate"] == 0.0 and s["ci"] == [None, None]
    # weights p/q <= 1/alpha: P <= Q(C) / alpha <= -ln(0.05) / (n alpha)
    assert s["upper_bound"] == pytest.approx(2.995732273553991 / (1000 * 0.2), rel=1e-12)
    assert r.summary()["stop_reason"] == "n"
    # 10 draws: -ln(0.05) / (10 x 0.2) = 1.5 is no bound on a probability: it is 1, and
    # the rate's bound is the exposure's cut-ins per hour times 1
    r = evaluate(model, never, n=10, seed=0, batch_size=10, physical_bounds=False,
                 bootstrap=False, alpha=0.2, exposure={"n_events": 50.0, "hours": 2.0})
    s = r.summary()
    assert s["p_collision"]["upper_bound"] == 1.0
    assert s["rate_per_hour"]["upper_bound"] == pytest.approx(25.0, rel=1e-12)


def test_late_brake_runner_by_hand() -> None:
    runner = late_brake_runner(reaction=1.0, decel=4.0)
    x = np.zeros((4, 8))
    # dv, gap: hit before braking (10 m/s, 5 m: closed in 0.5 s); hit while braking
    # (5 m left after 1 s, 10^2 - 2 * 4 * 5 = 60); missed (dv 2, 20 m); opening (dv -3)
    x[:, 6] = [10.0, 10.0, 2.0, -3.0]
    x[:, 7] = [5.0, 15.0, 20.0, 2.0]
    out = runner(x, np.zeros(4, dtype=np.uint64))
    assert out.collided.tolist() == [True, True, False, False]
    assert out.impact_speed.tolist() == pytest.approx([10.0, math.sqrt(60.0), 0.0, 0.0])


def test_region_rate_is_conditional_on_the_region(model: CutInGMM) -> None:
    j = model.features_.index("dv")
    tr = model.transforms_[j]
    # A = {dv > 1 m/s}; C = {z_dv > c} with c beyond A's edge: C is inside A and
    # P(C | A) = P(C) / P(A), both half-space masses
    z_edge = (1.0 - tr.loc) / tr.scale
    a = np.zeros(model.n_features)
    a[j] = -1.0
    c = z_edge + 2.5
    p_true = _mass(model, a, -c) / _mass(model, a, -z_edge)
    r = evaluate(model, halfspace_runner(model, a, -c), constraints=["dv>1"], seed=4,
                 batch_size=1000, physical_bounds=False, bootstrap=False, n=4000)
    s = r.summary()
    assert s["constraints"] == ["dv>1"]
    assert s["region_probability"]["estimate"] == pytest.approx(_mass(model, a, -z_edge),
                                                                rel=0.1)
    lo, hi = s["p_collision"]["ci"]
    assert lo < p_true < hi
    assert s["p_collision"]["rhw"] < 0.5


def _twin(model: CutInGMM, reps: int) -> CutInGMM:
    """A copy of ``model`` whose ``reps`` bootstrap replicates are all the model itself."""
    twin = CutInGMM.from_dict(model.to_dict())
    twin.bootstrap_ = {"weights": [model.weights_.tolist()] * reps,
                       "means": [model.means_.tolist()] * reps,
                       "covariances": [model.covariances_.tolist()] * reps}
    return twin


def test_model_interval_collapses_when_every_replicate_is_the_model(model: CutInGMM
                                                                   ) -> None:
    a, b, _ = _rare_halfspace(model, 1e-4)
    twin = _twin(model, 5)
    hours = 50.0
    exp = Exposure(n_events=300, hours=hours, km=None, source="test")
    r = evaluate(twin, halfspace_runner(twin, a, b), n=1000, seed=1, batch_size=500,
                 physical_bounds=False, exposure=exp)
    s = r.summary()
    p = s["p_collision"]["estimate"]
    assert s["p_collision"]["model_ci"] == pytest.approx([p, p], rel=1e-9)
    assert s["rate_per_hour"]["estimate"] == pytest.approx(300 / hours * p, rel=1e-12)
    assert s["rate_per_1e6_km"] is None


def test_model_replicates_survive_a_weight_that_underflows(model: CutInGMM) -> None:
    """The replicates' ``sum w p_b / p`` is ``sum p_b / q``: a collided row whose model
    density is far below a replicate's (``p_b / p`` overflows, ``w = p / q`` underflows to
    0) still gives finite replicates, equal to the plain formula on the other rows."""
    a, b, _ = _rare_halfspace(model, 1e-3)
    reps = 4
    twin = _twin(model, reps)
    r = evaluate(twin, halfspace_runner(twin, a, b), n=1000, seed=2, batch_size=500,
                 physical_bounds=False)
    pb_b = np.ones(reps)
    plain = r._model_replicates("collided", pb_b)
    # by hand on the unchanged rows: (1/N) sum_i w_i p_b(z_i) / p(z_i) (replicates = p)
    y = np.concatenate([np.where(c.collided, c.weights, 0.0) for c in r.counted_chunks])
    assert plain == pytest.approx(np.full(reps, y.sum() / r.counted_runs), rel=1e-9)
    c0 = r.counted_chunks[0]
    i = int(np.flatnonzero(c0.collided)[0])
    c0.log_p[i] = -900.0  # p / q underflows; the replicates' p_b stays as it was
    c0.weights[i] = math.exp(-900.0 - c0.log_q[i])
    with np.errstate(over="raise", invalid="raise"):
        got = r._model_replicates("collided", pb_b)
    assert np.all(np.isfinite(got))
    assert got == pytest.approx(plain, rel=1e-12)


def test_records_carry_weights_and_outcomes(model: CutInGMM) -> None:
    a, b, _ = _rare_halfspace(model, 1e-3)
    r = evaluate(model, halfspace_runner(model, a, b), n=400, seed=0, batch_size=200,
                 physical_bounds=False, bootstrap=False)
    recs = r.records()
    assert len(recs) == 400 and recs[0]["run"] == 0 and recs[-1]["chunk"] == 1
    # the estimate is the mean weight of the collided runs over the counted chunks' runs
    counted = [x for x in recs if x["counted"]]
    assert counted
    total = sum(x["weight"] for x in counted if x["collided"])
    assert total / len(counted) == pytest.approx(r.summary()["p_collision"]["estimate"],
                                                 rel=1e-12)
    assert {"p_y1", "gap", "seed", "log_p", "log_q", "part", "impact_speed"} <= set(recs[0])


@pytest.mark.parametrize("kwargs, field", [({"n": 0}, "n"), ({"rhw": 0}, "rhw"),
                                           ({"seed": -1}, "seed"),
                                           ({"batch_size": 0}, "batch_size"),
                                           ({"alpha": 0.0}, "alpha"),
                                           ({"alpha": 0.25}, "alpha")])
def test_bad_settings_name_the_field(model: CutInGMM, kwargs: dict[str, object],
                                     field: str) -> None:
    with pytest.raises(SamplerError) as err:
        evaluate(model, late_brake_runner(), **kwargs)  # type: ignore[arg-type]
    assert err.value.field == field
