"""riskcore.sut: hand-computed closed-loop runs, the protocol, determinism, the limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riskcore.sut import (
    BUILTIN_SUTS,
    CutInBatch,
    Observation,
    Observations,
    RunBatch,
    SimSettings,
    SutError,
    compare_careful,
    make_sut,
    per_run,
    simulate,
)

EL, EW = 4.5, 1.8


def leader_batch(gaps: list[float], v_lead: list[float], v_ego: list[float], *,
                 duration: float = 60.0, y: float = 0.0, h: float = 0.1,
                 t_p: float = 0.0) -> CutInBatch:
    """A leader at constant speed straight ahead (bumper-to-bumper gap at t = 0)."""
    t = np.round(np.arange(round(duration / h) + 1) * h, 12)
    n = len(gaps)
    cx = np.array([[g + EL] for g in gaps]) + np.outer(v_lead, t)
    return CutInBatch(t=t, lane_width=3.75, ego_v0=np.array(v_ego, dtype=float),
                      ego_length=EL, ego_width=EW, cx=cx, cy=np.full((n, t.size), y),
                      cpsi=np.zeros((n, t.size)), cv=np.outer(v_lead, np.ones(t.size)),
                      ca=np.zeros((n, t.size)), c_length=np.full(n, EL),
                      c_width=np.full(n, EW), t_p=np.full(n, t_p), t_cross=np.zeros(n))


def test_none_hits_a_slower_leader_at_the_hand_computed_time_and_speed() -> None:
    # gap 25.5 m closing at 5 m/s: contact at 5.1 s with 5 m/s
    b = leader_batch([25.5], [20.0], [25.0])
    r = simulate(make_sut("none"), b, seeds=0)
    assert r.collided[0]
    assert r.t_contact[0] == pytest.approx(5.1, abs=1e-9)
    assert r.impact_speed[0] == pytest.approx(5.0, abs=1e-9)
    assert r.min_gap[0] == 0.0 and r.end[0] == "contact"
    assert r.max_decel[0] == 0.0 and math.isnan(r.t_brake_rel_tp[0])


def test_none_beside_never_collides_and_ends_without_conflict() -> None:
    b = leader_batch([5.0], [20.0], [25.0], y=3.75, duration=2.0)
    r = simulate(make_sut("none"), b, seeds=0)
    assert not r.collided[0] and r.end[0] == "no_conflict"
    assert r.min_gap[0] == math.inf


def test_idm_settles_at_its_equilibrium_gap() -> None:
    # Treiber's equilibrium: s_e = (s0 + v T) / sqrt(1 - (v / v0)^4) at v = 20, v0 = 30
    s_e = (2.0 + 20.0 * 1.6) / math.sqrt(1.0 - (20.0 / 30.0) ** 4)
    b = leader_batch([s_e + 6.0], [20.0], [20.0], duration=200.0)
    r = simulate(make_sut("idm", v0=30.0), b, seeds=0, profiles=True,
                 settings=SimSettings(t_max=150.0))
    assert r.profiles is not None
    k = np.flatnonzero(~np.isnan(r.profiles["x"][0]))[-1]
    x, v = r.profiles["x"][0, k], r.profiles["v"][0, k]
    gap = (s_e + 6.0 + EL) + 20.0 * r.profiles["t"][k] - x - EL
    assert gap == pytest.approx(s_e, abs=0.05)
    assert v == pytest.approx(20.0, abs=0.01)


def test_idm_in_equilibrium_stays_there() -> None:
    s_e = (2.0 + 20.0 * 1.6) / math.sqrt(1.0 - (20.0 / 30.0) ** 4)
    b = leader_batch([s_e], [20.0], [20.0], duration=10.0)
    r = simulate(make_sut("idm", v0=30.0), b, seeds=0, settings=SimSettings(t_max=10.0))
    assert r.min_gap[0] == pytest.approx(s_e, abs=1e-9)
    assert r.max_decel[0] < 1e-9 and r.max_jerk[0] < 1e-9


def test_acc_settles_at_its_time_gap() -> None:
    # k1 (gap - s0 - 1.1 v) + k2 (v_l - v) = 0 at v = v_l = 20: gap = 2 + 22 = 24 m
    b = leader_batch([30.0], [20.0], [20.0], duration=200.0)
    r = simulate(make_sut("acc", v_set=30.0), b, seeds=0, profiles=True,
                 settings=SimSettings(t_max=150.0))
    assert r.profiles is not None
    k = np.flatnonzero(~np.isnan(r.profiles["x"][0]))[-1]
    gap = 30.0 + EL + 20.0 * r.profiles["t"][k] - r.profiles["x"][0, k] - EL
    assert gap == pytest.approx(24.0, abs=0.05)
    assert not r.collided[0]


def test_aeb_fires_at_the_hand_computed_time_and_stops_short() -> None:
    # ACC switched off (gains 0): TTC = (60 - 20 t) / 20 < 1.5 first at the step t = 1.51
    b = leader_batch([60.0], [10.0], [30.0], duration=10.0)
    sut = make_sut("acc_aeb", k0=0.0, k1=0.0, k2=0.0)
    r = simulate(sut, b, seeds=0)
    assert r.t_brake_rel_tp[0] == pytest.approx(1.51, abs=1e-9)
    # from 1.51 s: gap 60 - 20 * 1.51, jerk 12.65 up to 9 m/s², until v_rel = 0
    j, a, vr = 12.65, 9.0, 20.0
    t1 = a / j
    gap0 = 60.0 - 20.0 * 1.51
    used = vr * t1 - j * t1 ** 3 / 6 + (vr - j * t1 ** 2 / 2) ** 2 / (2 * a)
    assert not r.collided[0]
    assert r.min_gap[0] == pytest.approx(gap0 - used, abs=2e-3)
    assert r.max_decel[0] == pytest.approx(9.0, abs=1e-12)
    assert r.max_jerk[0] == pytest.approx(12.65, abs=1e-9)


def test_braking_to_standstill_never_reverses() -> None:
    class Brake:
        name = "brake"

        def reset(self, n: int, seeds: np.ndarray) -> None:
            pass

        def act(self, obs: Observations) -> np.ndarray:
            return np.full(obs.t.shape[0], -20.0)

    b = leader_batch([500.0], [20.0], [10.0], duration=5.0)
    r = simulate(Brake(), b, seeds=0, profiles=True, settings=SimSettings(t_max=5.0))
    assert r.profiles is not None
    v = r.profiles["v"][0]
    v = v[~np.isnan(v)]
    assert v.min() == 0.0 and np.all(np.diff(v) <= 0.0)
    # clipped to 9 m/s² with the 12.65 m/s³ ramp: stops after 9/12.65 + (10 - 9²/(2*12.65))/9
    t_stop = 9 / 12.65 + (10 - 81 / (2 * 12.65)) / 9
    k_stop = int(np.argmax(v == 0.0))
    assert r.profiles["t"][k_stop] == pytest.approx(t_stop, abs=0.011)
    assert r.max_decel[0] == 9.0


class PlainIDM:
    """IDM for one run, written plainly (the reference of the batched one)."""

    def reset(self, seed: int) -> None:
        self.v0: float | None = None

    def act(self, obs: Observation) -> float:
        if self.v0 is None:
            self.v0 = max(obs.ego_v, 0.1)
        v = obs.ego_v
        free = 1.0 - (v / self.v0) ** 4.0
        if obs.present[0] and obs.lane[0] == 0 and obs.dx[0] > 0:
            s = max(float(obs.gap[0]), 0.01)
            s_star = 2.0 + max(0.0, v * 1.6 + v * (v - obs.vx[0]) /
                               (2.0 * math.sqrt(0.73 * 1.67)))
            return 0.73 * (free - (s_star / s) ** 2)
        return 0.73 * free


def test_per_run_adapter_equals_the_batched_sut() -> None:
    b = leader_batch([15.0, 40.0, 80.0], [20.0, 15.0, 25.0], [25.0, 30.0, 20.0],
                     duration=20.0)
    fast = simulate(make_sut("idm"), b, seeds=[1, 2, 3])
    slow = simulate(per_run(PlainIDM, "plain_idm"), b, seeds=[1, 2, 3])
    for name in RunBatch.FIELDS:
        np.testing.assert_allclose(getattr(fast, name).astype(float) if getattr(
            fast, name).dtype.kind != "U" else 0, getattr(slow, name).astype(float) if
            getattr(slow, name).dtype.kind != "U" else 0, rtol=1e-9, atol=1e-9)
    assert list(fast.end) == list(slow.end)


class Jitter:
    """A random SUT: commands drawn per run from the run's seed."""

    name = "jitter"

    def reset(self, n: int, seeds: np.ndarray) -> None:
        self.rngs = [np.random.default_rng(int(s)) for s in seeds]

    def act(self, obs: Observations) -> np.ndarray:
        return np.array([r.uniform(-15.0, 5.0) for r in self.rngs])


def _bytes(r: RunBatch) -> bytes:
    return b"".join(np.ascontiguousarray(getattr(r, k)).tobytes() for k in RunBatch.FIELDS)


def test_same_seeds_same_bytes_and_other_seeds_differ() -> None:
    b = leader_batch([20.0, 30.0], [20.0, 18.0], [25.0, 26.0], duration=15.0)
    one = simulate(Jitter(), b, seeds=[7, 8])
    two = simulate(Jitter(), b, seeds=[7, 8])
    other = simulate(Jitter(), b, seeds=[9, 8])
    assert _bytes(one) == _bytes(two)
    assert _bytes(one) != _bytes(other)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), a_max=st.floats(2.0, 10.0),
       jerk=st.floats(2.0, 40.0), period=st.sampled_from([0.01, 0.05, 0.1]))
def test_the_ego_never_exceeds_its_limits(seed: int, a_max: float, jerk: float,
                                          period: float) -> None:
    b = leader_batch([20.0, 40.0], [10.0, 25.0], [25.0, 20.0], duration=8.0)
    s = SimSettings(a_brake_max=a_max, jerk_max=jerk, update_period=period, t_max=8.0)
    r = simulate(Jitter(), b, seeds=seed, settings=s, profiles=True)
    assert np.all(r.max_decel <= a_max + 1e-12)
    assert np.all(r.max_jerk <= jerk + 1e-9)
    assert r.profiles is not None
    v = r.profiles["v"]
    assert np.all(v[~np.isnan(v)] >= 0.0)


def test_a_braking_sut_hits_no_faster_than_none() -> None:
    b = leader_batch([5.0, 10.0, 25.0], [10.0, 15.0, 5.0], [30.0, 30.0, 30.0])
    none = simulate(make_sut("none"), b, seeds=0)
    for name in ("idm", "acc", "acc_aeb"):
        r = simulate(make_sut(name), b, seeds=0)
        assert np.all(r.impact_speed <= none.impact_speed + 1e-9), name


def test_compare_careful_by_hand() -> None:
    def rb(coll: list[bool], speed: list[float]) -> RunBatch:
        n = len(coll)
        z = np.zeros(n)
        return RunBatch(np.array(coll), np.array(speed), z, z, z, z, z, z, z, z, z, z,
                        np.zeros(n, bool), np.zeros(n, bool), z, z, z,
                        np.array(["x"] * n))
    sut = rb([True, False, True, True, False], [3.0, 0.0, 2.0, 4.0, 0.0])
    careful = rb([False, True, True, True, False], [0.0, 2.0, 3.0, 4.0, 0.0])
    assert list(compare_careful(sut, careful)) == ["worse", "better", "better", "same",
                                                   "same"]


def test_bad_inputs_name_the_field() -> None:
    b = leader_batch([20.0], [20.0], [25.0], duration=2.0)
    with pytest.raises(SutError, match="seeds"):
        simulate(make_sut("none"), b, seeds=[1, 2])
    with pytest.raises(SutError, match="dt"):
        SimSettings(dt=0.0)
    with pytest.raises(SutError, match="update_period"):
        SimSettings(update_period=0.015)
    with pytest.raises(SutError, match="unknown built-in"):
        make_sut("nope")
    with pytest.raises(SutError, match="idm: unknown parameter"):
        make_sut("idm", gain=1.0)
    with pytest.raises(SutError, match="ego_v0"):
        leader_batch([20.0], [20.0], [-1.0])
    assert SimSettings.from_dict(SimSettings(dt=0.02).to_dict()) == SimSettings(dt=0.02)


def test_every_builtin_has_a_source_and_runs() -> None:
    b = leader_batch([10.0], [15.0], [25.0], duration=10.0)
    for name, spec in BUILTIN_SUTS.items():
        assert spec.source and spec.summary
        r = simulate(spec.factory(), b, seeds=0)
        assert r.sut == name and len(r) == 1


class _Hidden:
    """A built-in without its compiled policy: the step loop every SUT takes."""

    def __init__(self, name: str, **params: float) -> None:
        self._sut = make_sut(name, **params)
        self.name = name

    def reset(self, n: int, seeds: np.ndarray) -> None:
        self._sut.reset(n, seeds)

    def act(self, obs: Observations) -> np.ndarray:
        return self._sut.act(obs)


def _wide_sample(n: int, seed: int) -> list:
    """Generated cut-ins over typical highway ranges (closing and opening, near and far:
    benchmarks/bench_sut.py's batch)."""
    from sampler import BuilderError, build_scenario

    rng = np.random.default_rng(seed)
    out: list = []
    while len(out) < n:
        p = {"p_y1": rng.choice([-1, 1]) * rng.uniform(0.05, 0.2),
             "p_t": rng.uniform(1.5, 3.0), "p_a1": rng.uniform(-3.0, 1.0),
             "p_a2": rng.uniform(-1.0, 3.0), "p_a3": rng.uniform(0.0, 3.0),
             "p_v0": rng.uniform(15.0, 35.0), "dv": rng.uniform(-2.0, 10.0),
             "gap": rng.uniform(2.0, 40.0)}
        try:
            out.append(build_scenario(p))
        except BuilderError:
            continue
    return out


@pytest.fixture(scope="module")
def mixed_batch() -> CutInBatch:
    """40 ttc < 3 cut-ins and 40 of the wide sample."""
    from tests.riskcore.test_sut_reference import _ttc3_sample

    return CutInBatch.from_scenarios(_ttc3_sample(40, 3) + _wide_sample(40, 11))


@pytest.mark.parametrize("name", ["none", "idm", "acc", "acc_aeb"])
def test_the_compiled_path_equals_the_step_loop(name: str, mixed_batch: CutInBatch) -> None:
    """Both compiled loops ("fused", "stepwise") give the bytes of the Python step loop
    (the slow, straightforward reference: the SUT's numpy act on the batch's observations,
    one step at a time), on a ttc < 3 sample and a wide one, every step and with a held
    command."""
    b = mixed_batch
    for s in (SimSettings(), SimSettings(update_period=0.05)):
        slow = simulate(make_sut(name), b, seeds=5, settings=s, engine="loop")
        for engine in ("fused", "stepwise"):
            fast = simulate(make_sut(name), b, seeds=5, settings=s, engine=engine)
            assert _bytes(fast) == _bytes(slow), engine
        if s.update_period is None:
            # a SUT without the compiled hook takes the same loop
            assert _bytes(simulate(_Hidden(name), b, seeds=5, settings=s)) == _bytes(slow)
            if name != "none":
                assert slow.collided.any() and not slow.collided.all()
                assert np.isfinite(slow.t_brake_rel_tp).any()
            assert np.isfinite(slow.min_gap).any()


def test_an_unknown_engine_is_refused() -> None:
    b = leader_batch([20.0], [20.0], [25.0], duration=2.0)
    with pytest.raises(SutError, match="engine"):
        simulate(make_sut("idm"), b, seeds=0, engine="turbo")


def test_ttr_aeb_brakes_on_the_online_risk_and_avoids_what_none_hits() -> None:
    from riskcore import EgoFuture, ObjectState, RiskSettings, evaluate_scene

    # 20 m/s behind a 10 m/s leader, 40 m gap: none hits it at t = 4 s
    b = leader_batch([40.0], [10.0], [20.0], duration=10.0)
    none = simulate(make_sut("none"), b, seeds=0)
    assert none.t_contact[0] == pytest.approx(4.0, abs=1e-9)
    r = simulate(make_sut("ttr_aeb"), b, seeds=0)
    assert not r.collided[0] and r.min_gap[0] > 0.0
    t_fire = r.t_brake_rel_tp[0]  # t_p = 0
    assert 0.0 < t_fire < 4.0
    # independently: riskcore's scene evaluation, the ego at constant speed
    rs = RiskSettings()
    off = np.arange(rs.n_steps + 1) * rs.dt

    def r_dep(t: float) -> float:
        gap = 40.0 - 10.0 * t
        z = np.zeros(off.shape[0])
        ego = EgoFuture(x=np.asarray(20.0 * off, dtype=np.float64), y=z, psi=z, v=z + 20.0,
                        length=EL, width=EW)
        obj = ObjectState(id="c", x=gap + EL, y=0.0, psi=0.0, v=10.0, a0=0.0, omega0=0.0,
                          length=EL, width=EW)
        return float(evaluate_scene(ego, [obj]).r_dep)

    assert r_dep(t_fire) >= 0.5 > r_dep(t_fire - 0.1)


# --- hand-computed runs of the reference drivers (r157_cc, r157_cc_conflict, rss) ---------
#
# A cutter G0 = 30.02 m ahead (bumper to bumper) at 20 m/s, heading 0, slides from the next
# lane's centre (y = 3.75 m) into the ego's at 1.25 m/s (y = 0 from t = 3 s on, a grid
# point); the ego drives at 25 m/s: the gap closes at 5 m/s, gap(t) = G0 - 5 t. (The extra
# 0.02 m keeps the TTC gates' moments off the 0.01 s steps.)
G0 = 30.02

def _sliding_cutter(t_p: float) -> CutInBatch:
    h = 0.1
    t = np.round(np.arange(151) * h, 12)
    cx = G0 + EL + 20.0 * t
    cy = np.maximum(3.75 - 1.25 * t, 0.0)
    one = np.ones(t.size)
    return CutInBatch(t=t, lane_width=3.75, ego_v0=np.array([25.0]), ego_length=EL,
                      ego_width=EW, cx=cx[None, :], cy=cy[None, :],
                      cpsi=np.zeros((1, t.size)), cv=(20.0 * one)[None, :],
                      ca=np.zeros((1, t.size)), c_length=np.full(1, EL),
                      c_width=np.full(1, EW), t_p=np.full(1, t_p), t_cross=np.zeros(1))


def _braking_distance_used(v_rel: float, a: float, j: float) -> float:
    """How much a closing gap shrinks from the brake onset until the speeds are equal:
    the deceleration ramps at j up to a (t1 = a / j), then holds (the leader keeps its
    speed)."""
    t1 = a / j
    v1 = v_rel - j * t1 ** 2 / 2.0
    assert v1 > 0.0
    return v_rel * t1 - j * t1 ** 3 / 6.0 + v1 ** 2 / (2.0 * a)


# UN R157's careful driver: 0.774 g (7.593 m/s^2) ramped at 12.65 m/s^3, 0.75 s reaction
_CC_A, _CC_J, _CC_REACT = 0.774 * 9.81, 12.65, 0.75


def test_r157_cc_conflict_brakes_0_75_s_after_perception_by_hand() -> None:
    # perception: the cutter's centre has moved 0.375 m towards the lane at 0.375 / 1.25 =
    # 0.3 s; the gap is closing then, so the reaction starts at t_p and braking at 1.05 s
    t_p = 0.3
    r = simulate(make_sut("r157_cc_conflict"), _sliding_cutter(t_p), seeds=0)
    t_b = t_p + _CC_REACT
    assert r.t_brake_rel_tp[0] == pytest.approx(t_b - t_p, abs=1e-9)
    gap_b = G0 - 5.0 * t_b
    assert not r.collided[0]
    assert r.min_gap[0] == pytest.approx(gap_b - _braking_distance_used(5.0, _CC_A, _CC_J),
                                         abs=1e-3)
    assert r.max_decel[0] == pytest.approx(_CC_A, abs=1e-12)


def test_r157_cc_waits_for_ttc_below_2_s_then_reacts_by_hand() -> None:
    # JRC-FSM rule: after t_p = 0.3 s it waits until TTC = gap / 5 < 2 s, i.e. gap < 10 m
    # at t = 4.004 s, and brakes 0.75 s later at 4.754 s with 6.25 m left
    t_p = 0.3
    r = simulate(make_sut("r157_cc"), _sliding_cutter(t_p), seeds=0)
    t_b = (G0 - 10.0) / 5.0 + _CC_REACT
    assert r.t_brake_rel_tp[0] == pytest.approx(t_b - t_p, abs=1e-9)
    assert not r.collided[0]
    assert r.min_gap[0] == pytest.approx(G0 - 5.0 * t_b
                                         - _braking_distance_used(5.0, _CC_A, _CC_J), abs=1e-3)
    # a shorter gate (1 s: gap < 5 m at 5.004 s, braking at 5.754 s with 1.25 m left)
    # collides
    late = simulate(make_sut("r157_cc", critical_ttc=1.0), _sliding_cutter(t_p), seeds=0)
    assert late.collided[0]
    assert late.t_brake_rel_tp[0] == pytest.approx((G0 - 5.0) / 5.0 + _CC_REACT - t_p, abs=1e-9)


def test_rss_brakes_rho_after_both_safe_distances_are_violated_by_hand() -> None:
    # longitudinal safe distance (Shalev-Shwartz et al., rho 0.75, a_accel 3, b_min = b_max
    # = 6): 25*0.75 + 3*0.75^2/2 + (25 + 3*0.75)^2/12 - 20^2/12 = 48.1 m > every gap here.
    rho, a_lat, mu = 0.75, 1.0, 0.3
    d_long = 25 * rho + 3 * rho ** 2 / 2 + (25 + 3 * rho) ** 2 / 12 - 20 ** 2 / 12
    assert d_long > G0
    # lateral: the cutter's heading is 0, so its velocity towards the ego is 0 and the
    # safe distance is mu + a_lat rho^2 / 2 + (a_lat rho)^2 / (2 a_lat) = 0.8625 m; the
    # lateral clearance |y| - 1.8 falls below it at y = 2.6625 m: t = (3.75 - 2.6625) / 1.25
    d_lat = mu + a_lat * rho ** 2 / 2 + (a_lat * rho) ** 2 / (2 * a_lat)
    t_trig = (3.75 - (EW + d_lat)) / 1.25
    assert t_trig == pytest.approx(0.87)
    t_p = 0.3
    r = simulate(make_sut("rss"), _sliding_cutter(t_p), seeds=0)
    t_b = t_trig + rho
    assert r.t_brake_rel_tp[0] == pytest.approx(t_b - t_p, abs=1e-9)
    assert not r.collided[0]
    assert r.min_gap[0] == pytest.approx(G0 - 5.0 * t_b
                                         - _braking_distance_used(5.0, _CC_A, _CC_J), abs=1e-3)
