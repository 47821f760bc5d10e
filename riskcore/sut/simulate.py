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
from riskcore.sut.risk import drive_risk
from riskcore.sut.runs import RunBatch
from riskcore.sut.settings import SimSettings

__all__ = ["simulate"]

#: compiled loops of the built-ins by ``simulate(engine=...)``
_ENGINES = {"fused": _k.run_builtin, "stepwise": _k.run_builtin_stepwise}


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


def _drive(sut: SystemUnderTest, batch: CutInBatch, s: SimSettings, n_steps: int,
           x: NDArray[np.float64], v: NDArray[np.float64], a: NDArray[np.float64],
           active: NDArray[np.bool_], hist: NDArray[np.float64], prm: NDArray[np.float64],
           out: NDArray[np.float64], end_code: NDArray[np.int8], collided: NDArray[np.bool_],
           cutter: tuple[NDArray[np.float64], ...],
           keep: list[NDArray[np.float64]] | None) -> None:
    """The step loop of any SUT: observe, act, advance (module docstring)."""
    n = batch.n
    dt = s.dt
    upd = s.update_steps
    t_end = batch.t_end
    assert t_end is not None
    u = np.zeros(n)
    u_old = np.zeros(n)
    onset = np.zeros(n)
    name = str(getattr(sut, "name", "sut"))
    for k in range(n_steps):
        if k % upd == 0:
            # fresh arrays every time: a SUT may keep the previous observation
            ego = (np.empty(n), np.empty(n), np.empty(n))
            obj = [np.empty((n, 1)) for _ in range(11)]
            present = np.empty((n, 1), dtype=np.bool_)
            lane = np.empty((n, 1), dtype=np.int8)
            _k.observe(k, s.delay_steps, hist, x, v, a, active, batch.cx, batch.cy,
                       batch.cpsi, batch.cv, batch.ca, batch.c_length, batch.c_width, prm,
                       ego[0], ego[1], ego[2], present, obj[0], obj[1], obj[2], obj[3],
                       obj[4], obj[5], obj[6], obj[7], obj[8], obj[9], lane, obj[10])
            obs = Observations(ego[0], ego[1], ego[2], batch.ego_length, batch.ego_width,
                               batch.lane_width, present, obj[0], obj[1], obj[2], obj[3],
                               obj[4], obj[5], obj[6], obj[7], obj[8], obj[9], lane,
                               obj[10], upd * dt)
            cmd = np.asarray(sut.act(obs), dtype=np.float64)
            if cmd.shape != (n,):
                raise SutError(f"{name}.act: expected shape ({n},), got {cmd.shape}")
            if not np.all(np.isfinite(cmd[active])):
                raise SutError(f"{name}.act: returned a non-finite command")
            u_old[:] = u
            np.clip(cmd, -s.a_brake_max, s.a_accel_max, out=u)
            when = getattr(sut, "command_onset", None)
            if when is None:
                onset[:] = 0.0
            else:
                d = np.asarray(when, dtype=np.float64) - k * dt
                onset[:] = np.where(np.isnan(d), 0.0, np.clip(d, 0.0, dt))
        elif k % upd == 1:
            u_old[:] = u
            onset[:] = 0.0
        if keep is not None:
            keep.append(np.stack([x, v, a]).copy())
        left = _k.advance(k, u_old, u, onset, x, v, a, active, hist, batch.cx, batch.cy,
                          batch.cpsi, batch.cv, batch.ca, batch.c_length, batch.c_width,
                          batch.t_p, t_end, prm, out, end_code, collided)
        if left == 0:
            break


def simulate(sut: SystemUnderTest, batch: CutInBatch, *, seeds: ArrayLike | int,
             settings: SimSettings | None = None, profiles: bool = False,
             risk: bool = False, must_avoid_variant: str = "6",
             engine: str = "fused") -> RunBatch:
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
        ``r_dep_time_above``; with ``profiles`` also the r_dep and r_ind profiles). Costly (one
        Monte-Carlo scene per step of the batch's grid and run); NaN when False.
    must_avoid_variant : "6" or "2.4"
        The regulation's deceleration for ``must_avoid``.
    engine : "fused", "stepwise" or "loop"
        Built-in SUTs with a compiled policy (none, idm, acc, acc_aeb) run through one
        compiled loop, run after run, when there is no perception delay and no profile or
        risk is asked for: "fused" (default; ``kernels.run_builtin``, the run's state in
        local variables) or "stepwise" (``kernels.run_builtin_stepwise``, one compiled
        step function per step: the previous fast path, kept as the speed baseline).
        "loop": the Python step loop every SUT takes. All three give bit-identical
        results (tested); other SUTs always take the loop.

    Returns
    -------
    RunBatch
    """
    s = settings or SimSettings()
    if not isinstance(batch, CutInBatch):
        raise SutError(f"batch: expected a CutInBatch, got {type(batch).__name__}")
    if not isinstance(s, SimSettings):
        raise SutError(f"settings: expected SimSettings, got {type(s).__name__}")
    kernel = _ENGINES.get(engine) if isinstance(engine, str) else None
    if engine != "loop" and kernel is None:
        raise SutError(f"engine: expected 'fused', 'stepwise' or 'loop', got {engine!r}")
    n = batch.n
    seed_arr = _seeds(seeds, n)
    sut.reset(n, seed_arr)
    dt = s.dt
    n_steps = math.ceil(s.t_max / dt - 1e-9)
    x = np.zeros(n)
    v = batch.ego_v0.copy()
    a = np.zeros(n)
    active = np.ones(n, dtype=np.bool_)
    hist = np.zeros((n, s.delay_steps + 1))
    out = _k.new_outcomes(n)
    end_code = np.zeros(n, dtype=np.int8)
    collided = np.zeros(n, dtype=np.bool_)
    prm = np.empty(_k.N_PRM)
    prm[_k.P_DT] = dt
    prm[_k.P_H] = batch.dt
    prm[_k.P_JERK] = s.jerk_max
    prm[_k.P_EHL] = 0.5 * batch.ego_length
    prm[_k.P_EHW] = 0.5 * batch.ego_width
    prm[_k.P_INTRUDE] = 0.5 * batch.lane_width - INTRUSION_DEPTH
    prm[_k.P_TMAX] = s.t_max
    prm[_k.P_BRAKE] = s.brake_threshold
    prm[_k.P_RANGE] = s.sensor_range
    prm[_k.P_HALF_LANE] = 0.5 * batch.lane_width
    assert batch.t_end is not None
    cutter = (batch.cx, batch.cy, batch.cpsi, batch.cv, batch.ca, batch.c_length,
              batch.c_width)
    # built-ins run through a compiled loop (the same steps; tests prove equality)
    compiled = getattr(sut, "compiled", None) if kernel is not None else None
    fast = (compiled(batch.ego_v0) if callable(compiled) and s.delay_steps == 0
            and not profiles and not risk else None)
    upd = s.update_steps
    keep: list[NDArray[np.float64]] | None = [] if profiles or risk else None
    if fast is not None:
        kind, q, v_des = fast
        assert kernel is not None
        kernel(kind, q, v_des, upd, n_steps, -s.a_brake_max, s.a_accel_max, x, v, a,
               batch.cx, batch.cy, batch.cpsi, batch.cv, batch.ca, batch.c_length,
               batch.c_width, batch.t_p, batch.t_end, prm, out, end_code, collided)
    else:
        _drive(sut, batch, s, n_steps, x, v, a, active, hist, prm, out, end_code, collided,
               cutter, keep)
    names = np.asarray(_k.END_NAMES)
    intr_ttc = out[:, _k.INTR_TTC]
    intr_vrel = out[:, _k.INTR_VREL]
    end_time = out[:, _k.END_TIME].copy()
    m_av = must_avoid(intr_ttc, intr_vrel, must_avoid_variant)
    prof = None
    if keep is not None:
        keep.append(np.stack([x, v, a]).copy())
        arr = np.stack(keep, axis=2)  # (3, N, K)
        tk = np.arange(arr.shape[2]) * dt
        after = tk[None, :] > end_time[:, None] + 1e-12
        for c in range(3):
            arr[c][after] = np.nan
        prof = {"t": tk, "x": arr[0], "v": arr[1], "a": arr[2]}
    nan = np.full(n, np.nan)
    col = {name: out[:, c].copy() for name, c in (
        ("impact_speed", _k.IMPACT), ("t_contact", _k.T_CONTACT), ("min_ttc", _k.MIN_TTC),
        ("min_thw", _k.MIN_THW), ("min_gap", _k.MIN_GAP), ("max_decel", _k.MAX_DECEL),
        ("max_jerk", _k.MAX_JERK))}
    runs = RunBatch(
        collided=collided, **col, t_brake_rel_tp=out[:, _k.T_BRAKE] - batch.t_p,
        r_dep_peak=nan.copy(), r_ind_peak=nan.copy(),
        r_dep_time_above=nan.copy(), must_avoid=m_av, violation=m_av & collided,
        ttc_intrusion=intr_ttc.copy(), v_rel_intrusion=intr_vrel.copy(), end_time=end_time,
        end=names[end_code], sut=str(getattr(sut, "name", type(sut).__name__)),
        profiles=prof)
    if risk:
        assert prof is not None
        peak, peak_ind, above, r_prof = drive_risk(batch, prof["t"], prof["x"], prof["v"],
                                                   end_time)
        runs.r_dep_peak = peak
        runs.r_ind_peak = peak_ind
        runs.r_dep_time_above = above
        if profiles:
            prof["r_dep"] = r_prof
            # one object (the cutter): r_ind = r_dep at every step (riskcore.sut.risk)
            prof["r_ind"] = r_prof.copy()
            prof["t_batch"] = batch.t
    if not profiles:
        runs.profiles = None
    return runs
