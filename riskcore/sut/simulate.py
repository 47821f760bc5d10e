"""The closed-loop simulator: one SUT drives the ego of N cut-ins at once.

Per step of ``settings.dt`` (a Python loop over time, compiled loops over the runs):
the SUT is asked for its commands (every ``update_period``) with the observations of the
step (objects as of ``perception_delay`` before); every active run's ego integrates its
command clipped to ``[-a_brake_max, a_accel_max]`` under the jerk limit (closed form, no
reversing: :mod:`riskcore.sut.kernels`); contact is the rotated-box overlap of the
criticality record, checked at the step's end and refined by bisection inside the step to
floating-point resolution; the margins are updated. The cutter follows its script and
never reacts.

A run ends at contact or once its conflict is resolved, the same notion as the record's
``conflict_resolution``: after the cutter's script is over (``batch.t_end``; it then
drives straight at constant speed) either its box is clear of the ego's lane
(``no_conflict``), it is behind the ego and not faster (``left_behind``), or it is ahead
in the lane, the gap is not shrinking and the ego accelerates by at most 0.1 m/s²
(``settled``: a follower closing in on its leader from below counts as settled);
otherwise at ``t_max``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore.sut import kernels as _k
from riskcore.sut.batch import CutInBatch, Observations
from riskcore.sut.errors import SutError
from riskcore.sut.protocol import SystemUnderTest
from riskcore.sut.regulation import INTRUSION_DEPTH, must_avoid
from riskcore.sut.runs import RunBatch
from riskcore.sut.settings import SimSettings

__all__ = ["simulate"]


def _seeds(seeds: ArrayLike | int | None, n: int) -> NDArray[np.uint64]:
    if seeds is None:
        raise SutError("seeds: one seed per run is required (an int or shape (N,))")
    if isinstance(seeds, int | np.integer) and not isinstance(seeds, bool):
        if int(seeds) < 0:
            raise SutError(f"seeds: must be >= 0, got {seeds}")
        ss = np.random.SeedSequence(int(seeds))
        return np.asarray(ss.generate_state(n, dtype=np.uint64), dtype=np.uint64)
    arr = np.asarray(seeds)
    if arr.shape != (n,):
        raise SutError(f"seeds: expected shape ({n},), got {arr.shape}")
    if arr.dtype.kind not in "ui" or (arr.dtype.kind == "i" and np.any(arr < 0)):
        raise SutError("seeds: must be non-negative integers")
    return np.asarray(arr, dtype=np.uint64)


def simulate(sut: SystemUnderTest, batch: CutInBatch, *, seeds: ArrayLike | int,
             settings: SimSettings | None = None, profiles: bool = False,
             risk: bool = False, must_avoid_variant: str = "6") -> RunBatch:
    """Drive the ego of every run of ``batch`` with ``sut`` (module docstring).

    Parameters
    ----------
    sut : SystemUnderTest
        ``reset(N, seeds)`` is called first.
    batch : CutInBatch
    seeds : int or array of shape (N,)
        One seed per run (uint64), or an int from which N are derived
        (``SeedSequence(seed).generate_state``).
    settings : SimSettings, optional
    profiles : bool
        Keep the ego's x, v, a at every step (``RunBatch.profiles``; memory N x steps).
    risk : bool
        Wagner's r_dep / r_ind of the SUT's own drive (``r_dep_peak``, ``r_ind_peak``,
        ``r_dep_time_above``; with ``profiles`` also the r_dep profile). Costly (one
        Monte-Carlo scene per step of the batch's grid and run); NaN when False.
    must_avoid_variant : "6" or "2.4"
        The regulation's deceleration for ``must_avoid``.

    Returns
    -------
    RunBatch
    """
    s = settings or SimSettings()
    if not isinstance(batch, CutInBatch):
        raise SutError(f"batch: expected a CutInBatch, got {type(batch).__name__}")
    if not isinstance(s, SimSettings):
        raise SutError(f"settings: expected SimSettings, got {type(s).__name__}")
    n = batch.n
    seed_arr = _seeds(seeds, n)
    sut.reset(n, seed_arr)
    dt = s.dt
    h = batch.dt
    n_steps = math.ceil(s.t_max / dt - 1e-9)
    x = np.zeros(n)
    v = batch.ego_v0.copy()
    a = np.zeros(n)
    active = np.ones(n, dtype=np.bool_)
    hist = np.zeros((n, s.delay_steps + 1))
    collided = np.zeros(n, dtype=np.bool_)
    t_contact = np.full(n, np.nan)
    impact = np.zeros(n)
    min_gap = np.full(n, np.inf)
    min_ttc = np.full(n, np.inf)
    min_thw = np.full(n, np.inf)
    max_decel = np.zeros(n)
    max_jerk = np.zeros(n)
    t_brake = np.full(n, np.nan)
    end_time = np.full(n, np.nan)
    end_code = np.zeros(n, dtype=np.int8)
    intr_prev = np.full(n, np.inf)
    intr_t = np.full(n, np.nan)
    intr_ttc = np.full(n, np.nan)
    intr_vrel = np.full(n, np.nan)
    ehl = 0.5 * batch.ego_length
    ehw = 0.5 * batch.ego_width
    half_lane = 0.5 * batch.lane_width
    intrude_at = half_lane - INTRUSION_DEPTH
    assert batch.t_end is not None
    obs_arrays = (np.empty(n), np.empty(n), np.empty(n))
    obj = [np.empty((n, 1)) for _ in range(11)]
    present = np.zeros((n, 1), dtype=np.bool_)
    lane = np.zeros((n, 1), dtype=np.int8)
    u = np.zeros(n)
    upd = s.update_steps
    keep: list[NDArray[np.float64]] = []
    for k in range(n_steps):
        if k % upd == 0:
            _k.observe(k, dt, s.delay_steps, h, hist, x, v, a, active, batch.cx, batch.cy,
                       batch.cpsi, batch.cv, batch.ca, batch.c_length, batch.c_width, ehl,
                       half_lane, s.sensor_range, *obs_arrays, present, obj[0], obj[1],
                       obj[2], obj[3], obj[4], obj[5], obj[6], obj[7], obj[8], obj[9], lane,
                       obj[10])
            obs = Observations(obs_arrays[0], obs_arrays[1], obs_arrays[2],
                               batch.ego_length, batch.ego_width, batch.lane_width, present,
                               obj[0], obj[1], obj[2], obj[3], obj[4], obj[5], obj[6],
                               obj[7], obj[8], obj[9], lane, obj[10])
            cmd = np.asarray(sut.act(obs), dtype=np.float64)
            if cmd.shape != (n,):
                raise SutError(f"{getattr(sut, 'name', 'sut')}.act: expected shape ({n},), "
                               f"got {cmd.shape}")
            if not np.all(np.isfinite(cmd[active])):
                raise SutError(f"{getattr(sut, 'name', 'sut')}.act: returned a non-finite "
                               "command")
            np.clip(cmd, -s.a_brake_max, s.a_accel_max, out=u)
        if profiles:
            keep.append(np.stack([x, v, a]).copy())
        left = _k.advance(k, dt, h, s.jerk_max, u, x, v, a, active, hist, batch.cx,
                          batch.cy, batch.cpsi, batch.cv, batch.ca, batch.c_length,
                          batch.c_width, ehl, ehw, batch.t_p, batch.t_end, intrude_at,
                          s.t_max, s.brake_threshold, collided, t_contact, impact, min_gap,
                          min_ttc, min_thw, max_decel, max_jerk, t_brake, end_time,
                          end_code, intr_prev, intr_t, intr_ttc, intr_vrel)
        if left == 0:
            break
    names = np.asarray(_k.END_NAMES)
    m_av = must_avoid(intr_ttc, intr_vrel, must_avoid_variant)
    prof = None
    if profiles:
        keep.append(np.stack([x, v, a]).copy())
        arr = np.stack(keep, axis=2)  # (3, N, K)
        tk = np.arange(arr.shape[2]) * dt
        after = tk[None, :] > end_time[:, None] + 1e-12
        for c in range(3):
            arr[c][after] = np.nan
        prof = {"t": tk, "x": arr[0], "v": arr[1], "a": arr[2]}
    nan = np.full(n, np.nan)
    runs = RunBatch(
        collided=collided, impact_speed=impact, t_contact=t_contact, min_ttc=min_ttc,
        min_thw=min_thw, min_gap=min_gap, max_decel=max_decel, max_jerk=max_jerk,
        t_brake_rel_tp=t_brake - batch.t_p, r_dep_peak=nan.copy(), r_ind_peak=nan.copy(),
        r_dep_time_above=nan.copy(), must_avoid=m_av, violation=m_av & collided,
        ttc_intrusion=intr_ttc, v_rel_intrusion=intr_vrel, end_time=end_time,
        end=names[end_code], sut=str(getattr(sut, "name", type(sut).__name__)),
        profiles=prof)
    if risk:
        raise SutError("risk: Wagner's risk of the SUT's drive is not implemented yet")
    return runs
