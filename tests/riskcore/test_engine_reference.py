"""The fast engine against the straightforward reference (tests/riskcore/reference.py).

Random scenes (hypothesis) with random settings, ego futures (straight or curving,
accelerating or braking), object placements on and off collision courses and input
distributions: every TTR, evasion mask, collision step and risk must agree.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from riskcore import EgoFuture, InputSurfaces, ObjectState, RiskSettings, evaluate_scene
from tests.riskcore.reference import (
    RefObject,
    RefSettings,
    ref_ctra,
    ref_object,
    ref_r_dep,
)


def constant_surfaces(mean_a: float, std_a: float, mean_w: float,
                      std_w: float) -> InputSurfaces:
    """Surfaces that give the same distribution at every (v0, x0)."""
    def one(mean: float, std: float) -> dict[str, object]:
        return {"v0": [0.0], "x0": [0.0], "mean": [[mean]], "std": [[std]]}
    return InputSurfaces.from_dict({"format": "scengen.input-surfaces/1", "interim": True,
                                    "accel": one(mean_a, std_a), "turn": one(mean_w, std_w)})


finite = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}


@st.composite
def scenes(draw: st.DrawFn) -> dict[str, object]:
    dt = draw(st.sampled_from([0.1, 0.2, 0.25]))
    n_steps = draw(st.integers(3, 16))
    s = RefSettings(horizon=n_steps * dt, dt=dt, n_a=draw(st.integers(1, 4)),
                    n_omega=draw(st.integers(1, 4)),
                    t_pnr=draw(st.sampled_from([0.0, 0.3, 0.5])),
                    t_max=draw(st.sampled_from([1.0, 2.0])),
                    m=draw(st.sampled_from([0.0, 1.0, 3.0])),
                    brake_max=draw(st.floats(3.0, 10.0, **finite)),
                    accel_max=draw(st.floats(0.5, 4.0, **finite)),
                    lat_accel_max=draw(st.floats(2.0, 9.0, **finite)))
    # ego: CTRA with its own small inputs (curving, speeding up or braking)
    ev = draw(st.floats(0.0, 35.0, **finite))
    ea = draw(st.floats(-4.0, 2.0, **finite))
    ew = draw(st.floats(-0.2, 0.2, **finite))
    epsi = draw(st.floats(-math.pi, math.pi, **finite))
    ego = np.array([[*ref_ctra(0.0, 0.0, epsi, ev, ea, ew, k * dt),
                     max(0.0, ev + ea * min(k * dt, ev / -ea if ea < 0 else math.inf))]
                    for k in range(n_steps + 1)])
    el = draw(st.floats(3.0, 6.0, **finite))
    ew_ = draw(st.floats(1.5, 2.6, **finite))
    # object: meets the ego's future at time t_m with an offset (often a collision course)
    t_m = n_steps * dt * draw(st.floats(0.3, 1.0, **finite))
    k_m = min(round(t_m / dt), n_steps)
    ov = draw(st.floats(0.0, 35.0, **finite))
    opsi = epsi + draw(st.one_of(st.floats(-0.4, 0.4, **finite),
                                 st.floats(-math.pi, math.pi, **finite)))
    off = draw(st.tuples(st.floats(-6.0, 6.0, **finite), st.floats(-6.0, 6.0, **finite)))
    ox = ego[k_m, 0] + off[0] - ov * math.cos(opsi) * k_m * dt
    oy = ego[k_m, 1] + off[1] - ov * math.sin(opsi) * k_m * dt
    obj = RefObject(x=ox, y=oy, psi=opsi, v=ov, length=draw(st.floats(3.0, 6.0, **finite)),
                    width=draw(st.floats(1.5, 2.6, **finite)),
                    mean_a=draw(st.floats(-3.0, 2.0, **finite)),
                    std_a=draw(st.floats(0.05, 1.5, **finite)),
                    mean_w=draw(st.floats(-0.3, 0.3, **finite)),
                    std_w=draw(st.floats(0.005, 0.15, **finite)))
    return {"s": s, "ego": ego, "ego_size": (el, ew_), "obj": obj}


def _fast(scene: dict[str, object]):  # type: ignore[no-untyped-def]
    s = scene["s"]
    ego = scene["ego"]
    obj = scene["obj"]
    assert isinstance(s, RefSettings) and isinstance(ego, np.ndarray)
    assert isinstance(obj, RefObject)
    el, ew = scene["ego_size"]  # type: ignore[misc]
    rs = RiskSettings(horizon=s.horizon, dt=s.dt, n_a=s.n_a, n_omega=s.n_omega,
                      t_pnr=s.t_pnr, t_max=s.t_max, m=s.m, brake_max=s.brake_max,
                      accel_max=s.accel_max, lat_accel_max=s.lat_accel_max,
                      min_turn_radius=s.min_turn_radius)
    fut = EgoFuture(x=ego[:, 0], y=ego[:, 1], psi=ego[:, 2], v=ego[:, 3], length=el,
                    width=ew)
    state = ObjectState("to", obj.x, obj.y, obj.psi, obj.v, 0.0, 0.0, obj.length, obj.width)
    surf = constant_surfaces(obj.mean_a, obj.std_a, obj.mean_w, obj.std_w)
    return evaluate_scene(fut, [state], rs, surf)


@settings(max_examples=220, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_fast_engine_agrees_with_reference_ttr_for_ttr(scene: dict[str, object]) -> None:
    s = scene["s"]
    assert isinstance(s, RefSettings)
    ref = ref_object(scene["ego"], scene["ego_size"], scene["obj"], s)  # type: ignore[arg-type]
    fast = _fast(scene).objects[0]
    np.testing.assert_array_equal(fast.collision_time,
                                  np.where(ref["first"] >= 0, ref["first"] * s.dt, np.inf))
    np.testing.assert_array_equal(fast.ttr, ref["ttr"])
    np.testing.assert_array_equal(fast.evasion, ref["mask"])
    np.testing.assert_allclose(fast.weight, ref["p"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(fast.g, ref["g"], rtol=1e-12, atol=1e-14)
    assert math.isclose(fast.risk, float(ref["risk"]), rel_tol=1e-12, abs_tol=1e-14)


def test_the_random_scenes_exercise_every_branch() -> None:
    """The generator is not vacuous: seeded draws contain collisions of every kind."""
    kinds = {"none": 0, "avoidable": 0, "unavoidable": 0}
    masks = set()
    rng = np.random.default_rng(7)
    for _ in range(60):
        scene = _seeded_scene(rng)
        obj = _fast(scene).objects[0]
        kinds["none"] += int(np.isinf(obj.ttr).sum())
        kinds["unavoidable"] += int(((obj.ttr == 0) & (obj.evasion == 0)).sum())
        kinds["avoidable"] += int((obj.evasion != 0).sum())
        masks.update(int(m) for m in obj.evasion)
    assert all(v > 10 for v in kinds.values()), kinds
    assert {1, 2, 4} <= {m & b for m in masks for b in (1, 2, 4, 8)}


def _seeded_scene(rng: np.random.Generator) -> dict[str, object]:
    dt, n_steps = 0.1, 20
    s = RefSettings(horizon=n_steps * dt, dt=dt, n_a=3, n_omega=3)
    ev = rng.uniform(5, 30)
    ego = np.array([[ev * k * dt, 0.0, 0.0, ev] for k in range(n_steps + 1)])
    t_m = rng.uniform(0, 2)
    ov = rng.uniform(0, 30)
    opsi = rng.uniform(-0.5, 0.5)
    k_m = round(t_m / dt)
    obj = RefObject(x=ego[k_m, 0] + rng.uniform(-3, 3) - ov * math.cos(opsi) * k_m * dt,
                    y=rng.uniform(-3, 3) - ov * math.sin(opsi) * k_m * dt, psi=opsi, v=ov,
                    length=4.5, width=1.8, mean_a=0.0, std_a=1.0, mean_w=0.0, std_w=0.05)
    return {"s": s, "ego": ego, "ego_size": (4.5, 1.8), "obj": obj}


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_two_objects_r_dep_matches_enumeration_of_engine_outputs(seed: int) -> None:
    """r_dep of a real two-object scene equals eq. (8) enumerated over its outcomes."""
    rng = np.random.default_rng(seed)
    rs = RiskSettings(horizon=2.0, n_a=3, n_omega=4)
    fut = EgoFuture.constant_velocity(0, 0, 0, 20.0, settings=rs)
    objs = [ObjectState(f"o{k}", rng.uniform(5, 30), rng.uniform(-4, 4), rng.uniform(-.3, .3),
                        rng.uniform(5, 20), rng.uniform(-1, 1), rng.uniform(-.1, .1))
            for k in range(2)]
    res = evaluate_scene(fut, objs, rs, constant_surfaces(0.0, 1.5, 0.0, 0.1))
    expected = ref_r_dep([o.g for o in res.objects], [o.weight for o in res.objects])
    assert math.isclose(res.r_dep, expected, rel_tol=1e-12, abs_tol=1e-14)
    assert res.r_dep <= res.r_ind + 1e-12
