"""Factory of tiny hand-made highD recordings for tests (a few vehicles, 25 Hz).

Vehicles are described in the road frame of their direction (s along the driving
direction, y to the left); this module writes them in highD's image frame with its own,
deliberately plain code (per-frame loops), independent of ``datasets.synth``.

Lanes: upper markings 2.00;5.75;9.50 (direction 1: lane 2 right, lane 3 left), lower
markings 13.00;16.75;20.50 (direction 2: lane 5 left, lane 6 right). Road-frame lane
centres: direction 1: lane 2 y = 3.875, lane 3 y = 7.625; direction 2: lane 5 y = -14.875,
lane 6 y = -18.625.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from datasets import highd_columns as hc
from datasets.cutin_model import CutInParams, lateral_displacement, motion
from datasets.highd import HighDRecording

FPS = 25.0
ROAD = 400.0
UPPER = [2.0, 5.75, 9.5]
LOWER = [13.0, 16.75, 20.5]
CENTRE = {2: 3.875, 3: 7.625, 5: -14.875, 6: -18.625}
WIDTH = 3.75


@dataclass
class Vehicle:
    """A vehicle: direction, size, and its road-frame state per frame."""

    vid: int
    direction: int
    length: float
    width: float
    frames: np.ndarray
    s: np.ndarray
    y: np.ndarray
    v: np.ndarray
    psi: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if self.psi.size == 0:
            self.psi = np.zeros_like(self.s)


def p_for_lane_change(left: bool, p_t: float, v: float, **kw: float) -> CutInParams:
    """Parameters whose lateral displacement is exactly one lane (3.75 m) to the side."""
    target = WIDTH if left else -WIDTH
    base = dict(p_t=p_t, p_a1=0.0, p_a2=0.0, p_a3=0.0, p_v0=v, dv=0.0, gap=0.0)
    base.update(kw)
    p_y1 = target * np.pi / (2 * v * p_t**2)
    for _ in range(3):
        p_y1 *= target / lateral_displacement(CutInParams(p_y1=p_y1, **base))
    return CutInParams(p_y1=p_y1, **base)


def straight(vid: int, direction: int, lane: int, s0: float, v: float, n: int = 300,
             length: float = 4.5) -> Vehicle:
    frames = np.arange(1, n + 1)
    t = frames / FPS
    return Vehicle(vid, direction, length, 1.8, frames, s0 + v * t, np.full(n, CENTRE[lane]),
                   np.full(n, v))


def changing(vid: int, direction: int, lane: int, s_at_t0: float, t0: float,
             p: CutInParams, n: int = 300, length: float = 4.5) -> Vehicle:
    frames = np.arange(1, n + 1)
    m = motion(p, frames / FPS - t0)
    return Vehicle(vid, direction, length, 1.8, frames, s_at_t0 + m.x, CENTRE[lane] + m.y,
                   m.v, m.psi)


def chain(first: Vehicle, p2: CutInParams, t0_2: float) -> Vehicle:
    """Append a second lane change starting at t0_2 to a vehicle (same frames)."""
    t = first.frames / FPS
    k = int(np.searchsorted(t, t0_2))
    m = motion(p2, t - t0_2)
    s = first.s.copy()
    y = first.y.copy()
    v = first.v.copy()
    psi = first.psi.copy()
    s[k:] = first.s[k] + (m.x[k:] - m.x[k])
    y[k:] = first.y[k] + m.y[k:] - m.y[k]
    v[k:] = m.v[k:]
    psi[k:] = m.psi[k:]
    return Vehicle(first.vid, first.direction, first.length, first.width, first.frames, s, y,
                   v, psi)


def _lane_id(yc: float) -> int:
    markings = UPPER + LOWER
    return 1 + sum(1 for m in markings if yc > m)


def make_recording(vehicles: list[Vehicle], name: str = "07") -> HighDRecording:
    rows = []
    for veh in vehicles:
        for k, f in enumerate(veh.frames):
            vx = veh.v[k] * np.cos(veh.psi[k])
            vy = veh.v[k] * np.sin(veh.psi[k])
            if veh.direction == 2:
                xc, yc, xv, yv = veh.s[k], -veh.y[k], vx, -vy
            else:
                xc, yc, xv, yv = ROAD - veh.s[k], veh.y[k], -vx, vy
            rows.append({
                hc.FRAME: int(f), hc.TRACK_ID: veh.vid,
                hc.X: xc - veh.length / 2, hc.Y: yc - veh.width / 2,
                hc.WIDTH: veh.length, hc.HEIGHT: veh.width,
                hc.X_VELOCITY: xv, hc.Y_VELOCITY: yv,
                hc.X_ACCELERATION: 0.0, hc.Y_ACCELERATION: 0.0,
                hc.FRONT_SIGHT_DISTANCE: 0.0, hc.BACK_SIGHT_DISTANCE: 0.0,
                hc.DHW: 0.0, hc.THW: 0.0, hc.TTC: 0.0, hc.PRECEDING_X_VELOCITY: 0.0,
                hc.PRECEDING_ID: 0, hc.FOLLOWING_ID: 0,
                hc.LEFT_PRECEDING_ID: 0, hc.LEFT_ALONGSIDE_ID: 0, hc.LEFT_FOLLOWING_ID: 0,
                hc.RIGHT_PRECEDING_ID: 0, hc.RIGHT_ALONGSIDE_ID: 0, hc.RIGHT_FOLLOWING_ID: 0,
                hc.LANE_ID: _lane_id(yc), "_s": veh.s[k], "_dir": veh.direction,
            })
    tracks = pd.DataFrame(rows)
    # neighbours in the same lane, frame by frame (plain loops)
    for _, grp in tracks.groupby([hc.FRAME, hc.LANE_ID]):
        order = grp.sort_values("_s")
        idx = order.index.to_list()
        ids = order[hc.TRACK_ID].to_list()
        for j, i in enumerate(idx):
            if j + 1 < len(idx):
                tracks.loc[i, hc.PRECEDING_ID] = ids[j + 1]
            if j > 0:
                tracks.loc[i, hc.FOLLOWING_ID] = ids[j - 1]
    tracks = tracks.drop(columns=["_s", "_dir"]).sort_values([hc.TRACK_ID, hc.FRAME])
    tracks = tracks.reset_index(drop=True)
    meta_rows = []
    for veh in vehicles:
        lanes = tracks.loc[tracks[hc.TRACK_ID] == veh.vid, hc.LANE_ID].to_numpy()
        meta_rows.append({
            hc.TRACK_ID: veh.vid, hc.WIDTH: veh.length, hc.HEIGHT: veh.width,
            hc.INITIAL_FRAME: int(veh.frames[0]), hc.FINAL_FRAME: int(veh.frames[-1]),
            hc.NUM_FRAMES: len(veh.frames), hc.CLASS: "Car",
            hc.DRIVING_DIRECTION: veh.direction,
            hc.TRAVELED_DISTANCE: float(veh.s[-1] - veh.s[0]),
            hc.MIN_X_VELOCITY: float(veh.v.min()), hc.MAX_X_VELOCITY: float(veh.v.max()),
            hc.MEAN_X_VELOCITY: float(veh.v.mean()), hc.MIN_DHW: -1.0, hc.MIN_THW: -1.0,
            hc.MIN_TTC: -1.0, hc.NUMBER_LANE_CHANGES: int((np.diff(lanes) != 0).sum()),
        })
    meta = pd.DataFrame(meta_rows)
    rec_meta = pd.DataFrame([{
        hc.RECORDING_ID: int(name), hc.FRAME_RATE: FPS, hc.LOCATION_ID: 1,
        hc.SPEED_LIMIT: -1.0, hc.MONTH: "01.2018", hc.WEEKDAY: "Mon", hc.START_TIME: "10:00",
        hc.DURATION: len(tracks[hc.FRAME].unique()) / FPS, hc.TOTAL_DRIVEN_DISTANCE: 0.0,
        hc.TOTAL_DRIVEN_TIME: 0.0, hc.N_VEHICLES: len(vehicles), hc.N_CARS: len(vehicles),
        hc.N_TRUCKS: 0, hc.UPPER_LANE_MARKINGS: ";".join(f"{m:.2f}" for m in UPPER),
        hc.LOWER_LANE_MARKINGS: ";".join(f"{m:.2f}" for m in LOWER),
    }])
    return HighDRecording(name, rec_meta, meta, tracks)
