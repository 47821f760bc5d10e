"""A slow, obviously-correct reference of the reference drivers: a plain loop at 1 ms.

Shared by the scenario-level (tests/riskcore/test_criticality.py) and the sampler-level
(tests/sampler/test_criticality.py) checks.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from riskcore import boxes_overlap
from riskcore.criticality import CriticalitySettings
from riskcore.scenario import ConcreteScenario

L = 4.5  # both vehicles 4.5 m x 1.8 m: centre distance at contact = 4.5 m


def reference_drive(scen: ConcreteScenario, driver: str, s: CriticalitySettings,
                    h: float = 1e-3) -> tuple[bool, float]:
    """Plain loop at 1 ms: (collision, impact speed). Generated cut-ins only (ego on
    y = 0 at constant speed); the cutter linearly interpolated between its samples."""
    t = scen.t
    cut = scen.objects[0]
    ego = scen.ego
    tq = np.arange(t[0], t[-1] + 10.0, h)
    xc = np.interp(tq, t, cut.x)
    yc = np.interp(tq, t, cut.y)
    pc = np.interp(tq, t, cut.psi)
    vc = np.interp(tq, t, cut.v)
    after = tq > t[-1]
    xc[after] = cut.x[-1] + cut.v[-1] * math.cos(cut.psi[-1]) * (tq[after] - t[-1])
    yc[after] = cut.y[-1] + cut.v[-1] * math.sin(cut.psi[-1]) * (tq[after] - t[-1])
    # perception: the centre has moved 0.375 m towards the ego lane
    moved = np.abs(cut.y - cut.y[0])
    k = int(np.flatnonzero(moved >= s.wandering_zone)[0])
    t_p = t[k - 1] + (s.wandering_zone - moved[k - 1]) / (moved[k] - moved[k - 1]) * 0.1
    x = float(ego.x[0])
    v = float(ego.v[0])
    a = 0.0
    braking_from = math.inf
    xs = np.empty(tq.shape[0])
    vs = np.empty(tq.shape[0])
    for i, ti in enumerate(tq):
        xs[i], vs[i] = x, v
        if braking_from == math.inf:
            gap = xc[i] - x - L
            closing = v - vc[i] * math.cos(pc[i])
            # a conflict develops: the cutter ahead, the gap closed, or closing with TTC
            # below critical_ttc (inf: any closing gap)
            if driver == "r157" and ti >= t_p and xc[i] > x and (
                    gap <= 0 or (closing > 0 and (s.critical_ttc == math.inf
                                                  or gap < s.critical_ttc * closing))):
                braking_from = ti + s.reaction_time
            if driver == "rss" and xc[i] > x:
                rho = s.rss_response_time
                d_long = (v * rho + 0.5 * s.rss_accel_max * rho**2
                          + (v + rho * s.rss_accel_max) ** 2 / (2 * s.rss_brake_min)
                          - max(vc[i] * math.cos(pc[i]), 0.0) ** 2 / (2 * s.rss_brake_max))
                lat_gap = abs(yc[i]) - 0.9 - (2.25 * abs(math.sin(pc[i]))
                                              + 0.9 * abs(math.cos(pc[i])))
                toward = max(-math.copysign(1.0, yc[i]) * vc[i] * math.sin(pc[i]), 0.0)
                al = s.rss_lat_accel_max
                d_lat = (s.rss_lat_margin + (2 * toward + al * rho) * rho / 2
                         + (toward + al * rho) ** 2 / (2 * al))
                if gap < d_long and lat_gap < d_lat:
                    braking_from = ti + rho
        if ti >= braking_from:
            a = min(a + s.jerk * h, s.decel_max)
        x += v * h - 0.5 * a * h * h if v > 0 else 0.0
        v = max(v - a * h, 0.0)
    ego_boxes = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs),
                                 np.full_like(xs, L), np.full_like(xs, 1.8)])
    cut_boxes = np.column_stack([xc, yc, pc, np.full_like(xs, L), np.full_like(xs, 1.8)])
    hit = boxes_overlap(ego_boxes, cut_boxes)
    if not hit.any():
        return False, 0.0
    i = int(np.argmax(hit))
    rel = math.hypot(vs[i] - vc[i] * math.cos(pc[i]), vc[i] * math.sin(pc[i]))
    return True, rel


@st.composite
def generated_cut_ins(draw: st.DrawFn) -> dict[str, float]:
    """Parameter vectors of generated cut-ins for the reference checks: 3.6 m of lateral
    movement, closing or slightly opening gaps."""
    p_v0 = draw(st.floats(15.0, 35.0))
    p_t = draw(st.floats(1.2, 3.5))
    side = draw(st.sampled_from([-1.0, 1.0]))
    return {"p_y1": side * 3.6 * math.pi / (2.0 * p_v0 * p_t**2), "p_t": p_t,
            "p_a1": draw(st.floats(-2.0, 1.0)), "p_a2": 0.5,
            "p_a3": draw(st.floats(0.0, 3.0)), "p_v0": p_v0,
            "dv": draw(st.floats(-2.0, 15.0)), "gap": draw(st.floats(2.0, 40.0))}


def clear_outcome(record: dict[str, float | bool | str | None] | None, driver: str) -> bool:
    """False for near-misses and touches within a few cm: below both models' resolution."""
    assert record is not None
    if record[f"{driver}_collision"]:
        return float(record[f"{driver}_impact_speed"]) > 0.1  # type: ignore[arg-type]
    return float(record[f"{driver}_min_gap"]) > 0.05  # type: ignore[arg-type]
