"""Seeded synthetic recordings in exact highD format, with the ground truth of every cut-in.

SYNTHETIC DATA: recordings made here carry ``month = weekDay = "SYNTHETIC"`` in
``XX_recordingMeta.csv``, a ``SYNTHETIC.md`` file in their folder and a ground-truth file
``XX_groundtruth_SYNTHETIC.csv``; extraction labels their rows ``source = synthetic:XX``.

Traffic model (road frame per direction, 25 Hz, explicit time stepping):

- ``lanes_per_direction`` lanes per direction (widths drawn in [3.5, 4.0] m), a
  ``road_length`` m visible section; a track is recorded while the centre is inside it;
- ``vehicles`` vehicles arrive uniformly over the recording (and a warm-up), 50/50 per
  direction; trucks (``truck_share``) keep the right lane at about 23 m/s; cars choose a
  lane and a desired speed that grows to the left (about 25, 30, 35 m/s);
- car following by the Intelligent Driver Model (a = 1.2 m/s^2, b = 2 m/s^2, T = 1.2 s,
  s0 = 2 m); vehicles only enter when the entry is free;
- a share ``lane_change_share`` of cars attempts one lane change soon after entering: when
  the target lane has room ahead (and the follower there is not much faster), the car's
  motion is scripted with :func:`datasets.cutin_model.motion` for a parameter vector
  drawn here (p_t in [1.5, 3] s, |p_a1| in [0.3, 1.2] m/s^2, p_a3 in [0.8, 2.5] s,
  p_a2 in [-1, 2 p_t - 0.5] s, p_y1 solved so the car ends at the target lane centre), so
  the ground truth is exact; the followers react through the IDM.

Ground truth per lane change: the parameter vector, t0, the crossing moment
t0 + crossing_time(p, w / 2) (w = start-lane width), and, when a vehicle follows in the
target lane at the first frame after the crossing (the highD cut-in definition), its id,
dv and gap at the crossing moment (positions interpolated linearly between frames).
Values in the CSVs are rounded to 0.01 like highD's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from datasets import highd_columns as hc
from datasets.cutin_model import (
    PARAM_NAMES,
    CutInParams,
    crossing_time,
    lateral_displacement,
    motion,
)
from datasets.errors import DatasetError
from datasets.highd import HighDRecording, write_highd

__all__ = ["SyntheticRecording", "generate_recording", "write_synthetic"]

_IDM_A, _IDM_B, _IDM_T, _IDM_S0 = 1.2, 2.0, 1.2, 2.0
_ENTRY_S = -40.0
_PRE, _POST = 2.0, 2.0


@dataclass
class SyntheticRecording:
    """A synthetic recording and the ground truth of its lane changes."""

    recording: HighDRecording
    truth: pd.DataFrame  #: one row per lane change; ``is_cutin`` marks the cut-ins


@dataclass
class _Script:
    vid: int
    p: CutInParams
    t0: float
    k_first: int  # first step index of the script
    s: np.ndarray
    y: np.ndarray
    v: np.ndarray
    psi: np.ndarray
    a: np.ndarray
    w: np.ndarray
    lane_from: int
    lane_to: int
    width_from: float
    s_at_t0: float
    y_start: float


def _solve_p_y1(base: dict[str, float], target: float) -> float:
    """p_y1 giving lateral displacement ``target`` (m, signed): two secant steps."""
    v = base["p_v0"]
    guess = target * np.pi / (2.0 * max(v, 1.0) * base["p_t"] ** 2)
    for _ in range(2):
        d = lateral_displacement(CutInParams(**{**base, "p_y1": guess}))
        guess *= target / d
    return float(guess)


def generate_recording(
    seed: int, *, minutes: float = 15.0, vehicles: int = 1000, lanes_per_direction: int = 3,
    frame_rate: float = 25.0, road_length: float = 420.0, lane_change_share: float = 0.4,
    truck_share: float = 0.15, name: str = "01", warmup: float = 40.0,
) -> SyntheticRecording:
    """Simulate one recording (see the module docstring). Same arguments, same output.

    Parameters
    ----------
    seed : int
    minutes : float
        Recorded duration in minutes.
    vehicles : int
        Vehicles scheduled to enter (those entering during the warm-up or too late to be
        seen are not in the files).
    lanes_per_direction : int
        2 to 4.
    name : str
        Recording prefix (digits, like highD's ``01``).
    """
    if not 2 <= lanes_per_direction <= 4:
        raise DatasetError(f"lanes_per_direction: expected 2-4, got {lanes_per_direction}")
    if minutes <= 0 or vehicles < 1:
        raise DatasetError("minutes and vehicles must be positive")
    if not name.isdigit():
        raise DatasetError(f"name: expected digits like '01', got {name!r}")
    rng = np.random.default_rng(seed)
    n_l = lanes_per_direction
    dt = 1.0 / frame_rate
    # lane geometry: image markings; road-frame bounds per direction (right to left)
    w_upper = rng.uniform(3.5, 4.0, n_l)
    w_lower = rng.uniform(3.5, 4.0, n_l)
    m_upper = 8.0 + np.concatenate([[0.0], np.cumsum(w_upper)])
    m_lower = m_upper[-1] + 2.5 + np.concatenate([[0.0], np.cumsum(w_lower)])
    m_upper, m_lower = np.round(m_upper, 2), np.round(m_lower, 2)
    bounds = {1: m_upper.copy(), 2: np.sort(-m_lower)}
    centres = {d: 0.5 * (b[1:] + b[:-1]) for d, b in bounds.items()}
    widths = {d: np.diff(b) for d, b in bounds.items()}

    n_steps = round(minutes * 60.0 * frame_rate)
    k_begin = -round(warmup * frame_rate)
    # vehicles: entry step, direction, lane, class, size, desired speed
    n = vehicles
    entry_t = np.sort(rng.uniform(k_begin * dt, (n_steps - 10 * frame_rate) * dt, n))
    direction = rng.integers(1, 3, n)
    truck = rng.random(n) < truck_share
    lane_p = np.linspace(1.4, 0.6, n_l)
    lane_p /= lane_p.sum()
    lane = np.where(truck, 0, rng.choice(n_l, n, p=lane_p))
    length = np.where(truck, rng.uniform(12.0, 16.5, n), rng.uniform(4.1, 5.1, n))
    width = np.where(truck, 2.5, rng.uniform(1.75, 2.05, n))
    base_speed = 25.0 + 5.0 * lane
    vdes = np.where(truck, rng.normal(23.0, 1.0, n), rng.normal(base_speed, 2.0, n))
    vdes = np.clip(vdes, 15.0, 45.0)
    wants_lc = (~truck) & (rng.random(n) < lane_change_share)
    lc_s = np.where(wants_lc, rng.uniform(5.0, 40.0, n), np.inf)

    s = np.full(n, np.nan)
    y = np.full(n, np.nan)
    v = vdes.copy()
    psi = np.zeros(n)
    acc = np.zeros(n)
    omega = np.zeros(n)
    active = np.zeros(n, dtype=bool)
    entered = np.zeros(n, dtype=bool)
    gone = np.zeros(n, dtype=bool)
    script_of = np.full(n, -1)
    scripts: list[_Script] = []
    rec: list[tuple[np.ndarray, ...]] = []
    next_entry = 0

    for k in range(k_begin, n_steps + 1):
        t = k * dt
        # --- entries (in arrival order; a blocked lane delays only its own arrivals)
        for i in range(next_entry, n):
            if entry_t[i] > t:
                break
            if entered[i]:
                continue
            same = active & (direction == direction[i]) & (lane == lane[i])
            if same.any():
                j = np.flatnonzero(same)[np.argmin(s[same])]
                if s[j] - _ENTRY_S - 0.5 * (length[j] + length[i]) < 10.0 + 1.2 * v[i]:
                    continue
                v[i] = min(vdes[i], v[j] + 3.0)
            s[i] = _ENTRY_S
            y[i] = centres[int(direction[i])][lane[i]]
            active[i] = entered[i] = True
        while next_entry < n and entered[next_entry]:
            next_entry += 1
        idx = np.flatnonzero(active)
        if idx.size:
            # --- leaders in the same lane (by centre)
            key = direction[idx] * 10 + lane[idx]
            order = np.lexsort((s[idx], key))
            srt = idx[order]
            same_next = np.r_[key[order][1:] == key[order][:-1], False]
            lead = np.full(srt.size, -1)
            lead[same_next] = srt[1:][same_next[:-1]]
            free = script_of[srt] < 0
            i_f = srt[free]
            l_f = lead[free]
            vv = v[i_f]
            a = _IDM_A * (1.0 - (vv / vdes[i_f]) ** 4)
            has = l_f >= 0
            if has.any():
                li = l_f[has]
                gap = np.maximum(s[li] - s[i_f[has]] - 0.5 * (length[li] + length[i_f[has]]), 0.1)
                dvl = vv[has] - v[li]
                s_star = _IDM_S0 + np.maximum(
                    0.0, vv[has] * _IDM_T + vv[has] * dvl / (2.0 * np.sqrt(_IDM_A * _IDM_B)))
                a[has] -= _IDM_A * (s_star / gap) ** 2
            a = np.clip(a, -9.0, _IDM_A)
            v_new = np.maximum(vv + a * dt, 0.0)
            s[i_f] += 0.5 * (vv + v_new) * dt
            v[i_f] = v_new
            acc[i_f] = a
            # --- scripted vehicles
            for i in srt[~free]:
                sc = scripts[script_of[i]]
                m = k - sc.k_first
                s[i], y[i], v[i] = sc.s[m], sc.y[m], sc.v[m]
                psi[i], acc[i], omega[i] = sc.psi[m], sc.a[m], sc.w[m]
                if m == len(sc.s) - 1:
                    script_of[i] = -1
                    vdes[i] = v[i]
                    psi[i] = omega[i] = acc[i] = 0.0
            # lane by centre
            for d in (1, 2):
                sel = idx[direction[idx] == d]
                lane[sel] = np.clip(np.searchsorted(bounds[d], y[sel]) - 1, 0, n_l - 1)
            # --- lane-change decisions
            for i in idx[(script_of[idx] < 0) & (s[idx] >= lc_s[idx])]:
                lc_s[i] = np.inf
                sc_new = _try_lane_change(i, k, t, dt, rng, s, y, v, lane, direction, length,
                                          active, script_of, scripts, n_l, centres, widths,
                                          road_length)
                if sc_new is not None:
                    script_of[i] = len(scripts)
                    scripts.append(sc_new)
            # --- exits and recording
            out = active & (s > road_length + 40.0)
            active &= ~out
            gone |= out
            if k >= 1:
                vis = idx[(s[idx] >= 0.0) & (s[idx] <= road_length)]
                if vis.size:
                    rec.append((np.full(vis.size, k), vis, s[vis], y[vis], v[vis], psi[vis],
                                acc[vis], omega[vis]))
    if not rec:
        raise DatasetError("no vehicle was recorded: increase minutes or vehicles")
    cols = [np.concatenate(c) for c in zip(*rec, strict=True)]
    frame_no, vid, s_r, y_r, v_r, psi_r, a_r, w_r = cols
    return _assemble(name, frame_rate, minutes, road_length, m_upper, m_lower, bounds,
                     frame_no.astype(np.int64), vid.astype(np.int64), s_r, y_r, v_r, psi_r,
                     a_r, w_r, direction, length, width, truck, scripts, widths)


def _try_lane_change(
    i: int, k: int, t: float, dt: float, rng: np.random.Generator, s: np.ndarray,
    y: np.ndarray, v: np.ndarray, lane: np.ndarray, direction: np.ndarray,
    length: np.ndarray, active: np.ndarray, script_of: np.ndarray, scripts: list[_Script],
    n_l: int, centres: dict[int, np.ndarray], widths: dict[int, np.ndarray],
    road_length: float,
) -> _Script | None:
    d = int(direction[i])
    j = int(lane[i])
    if j == 0:
        jt = 1
    elif j == n_l - 1:
        jt = j - 1
    else:
        jt = j + 1 if rng.random() < 0.6 else j - 1
    same_dir = active & (direction == d)
    # no other manoeuvre nearby
    busy = same_dir & (script_of >= 0) & (np.abs(s - s[i]) < 150.0)
    if busy.any():
        return None
    p_t = float(rng.uniform(1.5, 3.0))
    p_a1 = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.2))
    p_a2 = float(rng.uniform(-1.0, 2.0 * p_t - 0.5))
    p_a3 = float(min(rng.uniform(0.8, 2.5), 2.0 * p_t + 1.0 - p_a2))
    t0 = t + _PRE + max(0.0, -p_a2)
    t_end = t0 + max(2.0 * p_t, p_a2 + p_a3) + _POST
    v_i = float(v[i])
    v_top = v_i + max(p_a1, 0.0) * p_a3
    if s[i] + v_top * (t_end - t + 2.0) > road_length - 5.0:
        return None
    for lane_chk in (jt, j):
        ahead = same_dir & (lane == lane_chk) & (s > s[i])
        if ahead.any():
            la = np.flatnonzero(ahead)[np.argmin(s[ahead])]
            gap = s[la] - s[i] - 0.5 * (length[la] + length[i])
            # the scripted car ignores its leader: keep a safe gap until the script ends
            gap_end = gap - max(0.0, v_top - v[la]) * (t_end - t)
            if gap_end < 15.0 + 0.8 * v_top:
                return None
    behind = same_dir & (lane == jt) & (s <= s[i])
    if behind.any():
        fb = np.flatnonzero(behind)[np.argmax(s[behind])]
        gap_b = s[i] - s[fb] - 0.5 * (length[fb] + length[i])
        # predicted bumper gap when the cutter crosses (about t0 + p_t) must stay >= 3 m
        v_low = v_i + min(p_a1, 0.0) * p_a3
        if gap_b - max(0.0, v[fb] - v_low) * (t0 + p_t - t) < 3.0:
            return None
    p_v0 = v_i + p_a1 * float(np.clip(-p_a2, 0.0, p_a3))
    y_from = float(centres[d][j])
    disp = float(centres[d][jt] - y_from)
    base = {"p_y1": 0.0, "p_t": p_t, "p_a1": p_a1, "p_a2": p_a2, "p_a3": p_a3,
            "p_v0": p_v0, "dv": 0.0, "gap": 0.0}
    p = CutInParams(**{**base, "p_y1": _solve_p_y1(base, disp)})
    n_k = round((t_end - t) / dt) + 1
    tau = (k + np.arange(n_k)) * dt - t0
    mo = motion(p, tau)
    x_now = float(mo.x[0])
    return _Script(
        vid=i, p=p, t0=t0, k_first=k, s=s[i] + (mo.x - x_now), y=y_from + mo.y, v=mo.v,
        psi=mo.psi, a=mo.a, w=mo.yaw_rate, lane_from=j, lane_to=jt,
        width_from=float(widths[d][j]), s_at_t0=float(s[i] - x_now), y_start=y_from,
    )


def _neighbour(
    key: np.ndarray, s: np.ndarray, half: np.ndarray, ids: np.ndarray, q_key: np.ndarray,
    q_s: np.ndarray, q_half: np.ndarray, span: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(preceding, alongside, following) ids of query points in the groups ``q_key``."""
    comb = key * span + s
    order = np.argsort(comb, kind="stable")
    comb_s, key_s, s_s, half_s, ids_s = comb[order], key[order], s[order], half[order], ids[order]
    pos = np.searchsorted(comb_s, q_key * span + q_s)
    n = len(comb_s)
    pre = np.zeros(len(q_s), dtype=np.int64)
    alo = np.zeros(len(q_s), dtype=np.int64)
    fol = np.zeros(len(q_s), dtype=np.int64)

    def valid(p: np.ndarray) -> np.ndarray:
        ok = (p >= 0) & (p < n)
        ok[ok] &= key_s[p[ok]] == q_key[ok]
        return ok

    def overlap(p: np.ndarray, ok: np.ndarray) -> np.ndarray:
        out = np.zeros(len(p), dtype=bool)
        out[ok] = np.abs(s_s[p[ok]] - q_s[ok]) < half_s[p[ok]] + q_half[ok]
        return out

    a_ok = valid(pos)
    a_ov = overlap(pos, a_ok)
    b_ok = valid(pos - 1)
    b_ov = overlap(pos - 1, b_ok)
    alo[a_ov] = ids_s[pos[a_ov]]
    only_b = b_ov & ~a_ov
    alo[only_b] = ids_s[pos[only_b] - 1]
    p_next = np.where(a_ov, pos + 1, pos)
    ok = valid(p_next)
    pre[ok] = ids_s[p_next[ok]]
    p_prev = np.where(b_ov, pos - 2, pos - 1)
    ok = valid(p_prev)
    fol[ok] = ids_s[p_prev[ok]]
    return pre, alo, fol


def _assemble(
    name: str, frame_rate: float, minutes: float, road_length: float, m_upper: np.ndarray,
    m_lower: np.ndarray, bounds: dict[int, np.ndarray], frame_no: np.ndarray,
    vid: np.ndarray, s: np.ndarray, y: np.ndarray, v: np.ndarray, psi: np.ndarray,
    a: np.ndarray, w: np.ndarray, direction: np.ndarray, length: np.ndarray,
    width: np.ndarray, truck: np.ndarray, scripts: list[_Script],
    widths: dict[int, np.ndarray],
) -> SyntheticRecording:
    # highD ids 1..N in order of first appearance
    first = pd.DataFrame({"vid": vid, "f": frame_no}).groupby("vid")["f"].min()
    first = first.sort_values(kind="stable")
    new_id = pd.Series(np.arange(1, len(first) + 1), index=first.index)
    hid = new_id.reindex(vid).to_numpy()
    d = direction[vid]
    L = length[vid]
    W = width[vid]
    flip = np.where(d == 1, -1.0, 1.0)
    # road -> image: direction 2: xc = s, yc = -y; direction 1: xc = road_length - s, yc = y
    xc = np.where(d == 1, road_length - s, s)
    yc = -flip * y
    vx_r = v * np.cos(psi)
    vy_r = v * np.sin(psi)
    ax_r = a * np.cos(psi) - v * w * np.sin(psi)
    ay_r = a * np.sin(psi) + v * w * np.cos(psi)
    all_m = np.concatenate([m_upper, m_lower])
    lane_id = np.searchsorted(all_m, yc) + 1
    # neighbours: groups (frame, direction, road lane index)
    lane_j = np.empty(len(s), dtype=np.int64)
    for dd in (1, 2):
        sel = d == dd
        lane_j[sel] = np.searchsorted(bounds[dd], y[sel]) - 1
    span = 4.0 * road_length
    key = (frame_no * 3 + d) * 8 + lane_j + 1
    half = 0.5 * L
    pre, fol = _same_lane(key, s, hid)
    lpre, lalo, lfol = _neighbour(key, s, half, hid, key + 1, s, half, span)
    rpre, ralo, rfol = _neighbour(key, s, half, hid, key - 1, s, half, span)
    idx_of = pd.Series(np.arange(len(s)), index=pd.MultiIndex.from_arrays([hid, frame_no]))
    p_row = idx_of.reindex(pd.MultiIndex.from_arrays([pre, frame_no])).to_numpy()
    has_p = pre != 0
    p_row_i = np.where(has_p, p_row, 0).astype(np.int64)
    dhw = np.where(has_p, s[p_row_i] - s - 0.5 * (L[p_row_i] + L), 0.0)
    v_x = np.round(flip * vx_r, 2)
    thw = np.where(has_p & (v > 0), dhw / np.maximum(v, 1e-9), 0.0)
    closing = has_p & (v > v[p_row_i])
    ttc = np.where(closing, dhw / np.where(closing, v - v[p_row_i], 1.0), 0.0)
    tracks = pd.DataFrame({
        hc.FRAME: frame_no, hc.TRACK_ID: hid,
        hc.X: np.round(xc - 0.5 * L, 2), hc.Y: np.round(yc - 0.5 * W, 2),
        hc.WIDTH: np.round(L, 2), hc.HEIGHT: np.round(W, 2),
        hc.X_VELOCITY: v_x, hc.Y_VELOCITY: np.round(-flip * vy_r, 2),
        hc.X_ACCELERATION: np.round(flip * ax_r, 2),
        hc.Y_ACCELERATION: np.round(-flip * ay_r, 2),
        hc.FRONT_SIGHT_DISTANCE: np.round(road_length - s, 2),
        hc.BACK_SIGHT_DISTANCE: np.round(s, 2),
        hc.DHW: np.round(dhw, 2), hc.THW: np.round(thw, 2), hc.TTC: np.round(ttc, 2),
        hc.PRECEDING_X_VELOCITY: np.where(has_p, v_x[p_row_i], 0.0),
        hc.PRECEDING_ID: pre, hc.FOLLOWING_ID: fol,
        hc.LEFT_PRECEDING_ID: lpre, hc.LEFT_ALONGSIDE_ID: lalo, hc.LEFT_FOLLOWING_ID: lfol,
        hc.RIGHT_PRECEDING_ID: rpre, hc.RIGHT_ALONGSIDE_ID: ralo,
        hc.RIGHT_FOLLOWING_ID: rfol, hc.LANE_ID: lane_id,
    }).sort_values([hc.TRACK_ID, hc.FRAME], kind="stable").reset_index(drop=True)
    meta = _tracks_meta(tracks, new_id, direction, truck, s, hid, v, dhw, thw, ttc, has_p,
                        closing)
    n_veh = len(meta)
    n_trucks = int((meta[hc.CLASS] == "Truck").sum())
    duration = minutes * 60.0
    rec_meta = pd.DataFrame({
        hc.RECORDING_ID: [int(name)], hc.FRAME_RATE: [frame_rate], hc.LOCATION_ID: [0],
        hc.SPEED_LIMIT: [-1.0], hc.MONTH: [hc.SYNTHETIC_MARK], hc.WEEKDAY: [hc.SYNTHETIC_MARK],
        hc.START_TIME: ["00:00"], hc.DURATION: [duration],
        hc.TOTAL_DRIVEN_DISTANCE: [float(np.round(meta[hc.TRAVELED_DISTANCE].sum(), 2))],
        hc.TOTAL_DRIVEN_TIME: [float(np.round(meta[hc.NUM_FRAMES].sum() / frame_rate, 2))],
        hc.N_VEHICLES: [n_veh], hc.N_CARS: [n_veh - n_trucks], hc.N_TRUCKS: [n_trucks],
        hc.UPPER_LANE_MARKINGS: [";".join(f"{m:.2f}" for m in m_upper)],
        hc.LOWER_LANE_MARKINGS: [";".join(f"{m:.2f}" for m in m_lower)],
    })
    recording = HighDRecording(name, rec_meta, meta, tracks)
    truth = _truth(name, frame_rate, scripts, new_id, frame_no, hid, s, v, L, lane_j, d)
    return SyntheticRecording(recording, truth)


def _same_lane(key: np.ndarray, s: np.ndarray, hid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.lexsort((s, key))
    k_s = key[order]
    same = k_s[1:] == k_s[:-1]
    pre_s = np.zeros(len(s), dtype=np.int64)
    fol_s = np.zeros(len(s), dtype=np.int64)
    pre_s[:-1][same] = hid[order][1:][same]
    fol_s[1:][same] = hid[order][:-1][same]
    pre = np.empty_like(pre_s)
    fol = np.empty_like(fol_s)
    pre[order] = pre_s
    fol[order] = fol_s
    return pre, fol


def _tracks_meta(
    tracks: pd.DataFrame, new_id: pd.Series, direction: np.ndarray, truck: np.ndarray,
    s: np.ndarray, hid: np.ndarray, v: np.ndarray, dhw: np.ndarray, thw: np.ndarray,
    ttc: np.ndarray, has_p: np.ndarray, closing: np.ndarray,
) -> pd.DataFrame:
    g = tracks.groupby(hc.TRACK_ID, sort=True)
    inv = pd.Series(new_id.index.to_numpy(), index=new_id.to_numpy())
    ids = g.size().index.to_numpy()
    sim = inv.reindex(ids).to_numpy()
    lane_changes = g[hc.LANE_ID].apply(lambda x: int((np.diff(x.to_numpy()) != 0).sum()))
    per = pd.DataFrame({"id": hid, "s": s, "v": v,
                        "dhw": np.where(has_p, dhw, np.nan), "thw": np.where(has_p, thw, np.nan),
                        "ttc": np.where(closing, ttc, np.nan)}).groupby("id")
    agg = per.agg(s_min=("s", "min"), s_max=("s", "max"), v_min=("v", "min"),
                  v_max=("v", "max"), v_mean=("v", "mean"), dhw=("dhw", "min"),
                  thw=("thw", "min"), ttc=("ttc", "min")).reindex(ids)
    return pd.DataFrame({
        hc.TRACK_ID: ids,
        hc.WIDTH: g[hc.WIDTH].first().to_numpy(),
        hc.HEIGHT: g[hc.HEIGHT].first().to_numpy(),
        hc.INITIAL_FRAME: g[hc.FRAME].min().to_numpy(),
        hc.FINAL_FRAME: g[hc.FRAME].max().to_numpy(),
        hc.NUM_FRAMES: g.size().to_numpy(),
        hc.CLASS: np.where(truck[sim], "Truck", "Car"),
        hc.DRIVING_DIRECTION: direction[sim],
        hc.TRAVELED_DISTANCE: np.round((agg["s_max"] - agg["s_min"]).to_numpy(), 2),
        hc.MIN_X_VELOCITY: np.round(agg["v_min"].to_numpy(), 2),
        hc.MAX_X_VELOCITY: np.round(agg["v_max"].to_numpy(), 2),
        hc.MEAN_X_VELOCITY: np.round(agg["v_mean"].to_numpy(), 2),
        hc.MIN_DHW: np.round(agg["dhw"].fillna(-1.0).to_numpy(), 2),
        hc.MIN_THW: np.round(agg["thw"].fillna(-1.0).to_numpy(), 2),
        hc.MIN_TTC: np.round(agg["ttc"].fillna(-1.0).to_numpy(), 2),
        hc.NUMBER_LANE_CHANGES: lane_changes.reindex(ids).to_numpy(),
    })


def _truth(
    name: str, frame_rate: float, scripts: list[_Script], new_id: pd.Series,
    frame_no: np.ndarray, hid: np.ndarray, s: np.ndarray, v: np.ndarray, L: np.ndarray,
    lane_j: np.ndarray, d: np.ndarray,
) -> pd.DataFrame:
    rows: list[dict[str, Any]] = []
    for sc in scripts:
        if sc.vid not in new_id.index:
            continue
        cid = int(new_id[sc.vid])
        p = sc.p
        tau_c = crossing_time(p, 0.5 * sc.width_from)
        t_c = sc.t0 + tau_c
        k_c = int(np.ceil(t_c * frame_rate - 1e-9))
        mo = motion(p, [tau_c])
        x_c = sc.s_at_t0 + float(mo.x[0])
        v_c = float(mo.v[0])
        mine = (hid == cid) & (frame_no == k_c)
        row: dict[str, Any] = {
            "event_id": "", "cutter_id": cid, "ego_id": 0, "is_cutin": False,
            "t_start": sc.t0, "t_cross": t_c, "frame_cross": k_c,
            "lane_width": sc.width_from, "side": "right" if p.p_y1 > 0 else "left",
            **{k: getattr(p, k) for k in PARAM_NAMES},
        }
        row["dv"] = row["gap"] = np.nan
        if mine.any():
            i_c = int(np.flatnonzero(mine)[0])
            dd = d[i_c]
            cand = (frame_no == k_c) & (d == dd) & (lane_j == sc.lane_to) & (s < s[i_c])
            if cand.any():
                f = np.flatnonzero(cand)[np.argmax(s[cand])]
                fid = int(hid[f])
                prev = np.flatnonzero((hid == fid) & (frame_no == k_c - 1))
                if prev.size:
                    g = int(prev[0])
                    frac = t_c * frame_rate - (k_c - 1)
                    x_f = s[g] + frac * (s[f] - s[g])
                    v_f = v[g] + frac * (v[f] - v[g])
                    row.update({
                        "ego_id": fid, "is_cutin": True, "dv": v_f - v_c,
                        "gap": x_c - x_f - 0.5 * (L[i_c] + L[f]),
                        "event_id": f"{name}-{cid}-{k_c}",
                    })
        rows.append(row)
    cols = ["event_id", "cutter_id", "ego_id", "is_cutin", *PARAM_NAMES, "t_start", "t_cross",
            "frame_cross", "lane_width", "side"]
    return pd.DataFrame(rows, columns=cols)


def write_synthetic(directory: str | Path, seed: int, **kwargs: Any) -> list[Path]:
    """Generate a recording (see :func:`generate_recording`) and write it with its truth.

    Writes ``XX_tracks.csv``, ``XX_tracksMeta.csv``, ``XX_recordingMeta.csv``,
    ``XX_groundtruth_SYNTHETIC.csv`` and ``SYNTHETIC.md`` into ``directory``.
    """
    out = generate_recording(seed, **kwargs)
    d = Path(directory)
    paths = write_highd(out.recording, d)
    name = out.recording.name
    truth_path = d / f"{name}_groundtruth_SYNTHETIC.csv"
    truth = out.truth.copy()
    truth.insert(0, "synthetic", True)
    truth.to_csv(truth_path, index=False)
    marker = d / "SYNTHETIC.md"
    marker.write_text(
        "# SYNTHETIC DATA\n\n"
        f"Recording {name} in this folder was generated by scengen (`datasets.synth`, "
        f"seed {seed}, options {kwargs}). It is not a highD recording and shows no real "
        "traffic. The ground truth of every lane change is in "
        f"`{truth_path.name}` (`is_cutin` marks the cut-ins).\n"
    )
    return [*paths, truth_path, marker]
