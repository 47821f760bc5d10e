"""Wagner's r_dep / r_ind of the SUT's own drive (``simulate(..., risk=True)``).

At every step of the batch's grid until a run's end, the scene "the cutter's state now,
the ego's actual future drive over riskcore's horizon" is scored by riskcore's engine
(:func:`riskcore.criticality.kernels.scene_risks`, the compiled one-object path of the
criticality record): with one object r_dep = r_ind. The ego's future after the run's end
is continued at constant velocity. The cutter's inputs a0 and omega0 are its acceleration
and its yaw rate (``batch.c_yaw_rate``; else the gradient of its heading over the grid).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from riskcore.criticality import kernels as _ck
from riskcore.evasion import MANOEUVRES
from riskcore.scene import _Engine, default_surfaces
from riskcore.settings import RiskSettings
from riskcore.sut.batch import CutInBatch

__all__ = ["drive_risk"]

FloatArray = NDArray[np.float64]

#: r_dep at or above this counts towards ``r_dep_time_above``
LEVEL = 0.5


def drive_risk(batch: CutInBatch, t_sim: FloatArray, ex: FloatArray, ev: FloatArray,
               end_time: FloatArray, rs: RiskSettings | None = None
               ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(r_dep peak, r_ind peak, time with r_dep >= 0.5 in s, r_dep (N, T) with NaN after
    the end) from the ego's drive ``ex``, ``ev`` (N, K) sampled at ``t_sim`` (K,)."""
    rs = rs or RiskSettings()
    surfaces = default_surfaces()
    eng = _Engine(rs, surfaces, MANOEUVRES)
    n, T = batch.n, batch.t.size
    offsets = np.arange(rs.n_steps + 1) * rs.dt
    prof = np.full((n, T), np.nan)
    peak = np.zeros(n)
    above = np.zeros(n)
    h = batch.dt
    for i in range(n):
        ks = np.flatnonzero(batch.t <= end_time[i] + 1e-9)
        if ks.size == 0:
            continue
        ok = ~np.isnan(ex[i])
        ts, xs, vs = t_sim[ok], ex[i, ok], ev[i, ok]
        tq = batch.t[ks][:, None] + offsets[None, :]
        x = np.interp(tq, ts, xs)
        v = np.interp(tq, ts, vs)
        late = tq > ts[-1]
        x = np.where(late, xs[-1] + vs[-1] * (tq - ts[-1]), x)
        v = np.where(late, vs[-1], v)
        zeros = np.zeros_like(x)
        m = rs.n_steps
        man_a = np.empty((ks.size, m, len(MANOEUVRES)))
        man_w = np.empty((ks.size, m, len(MANOEUVRES)))
        for j, man in enumerate(MANOEUVRES):
            man_a[:, :, j], man_w[:, :, j] = man.inputs(v[:, :m], rs)
        cv = batch.cv[i]
        w0 = (batch.c_yaw_rate[i] if batch.c_yaw_rate is not None
              else np.gradient(batch.cpsi[i], h))
        mean_a, std_a = surfaces.accel(cv, batch.ca[i])
        mean_w, std_w = surfaces.turn(cv, w0)
        dist = np.column_stack([mean_a, std_a, mean_w, std_w])[ks]
        out = np.full(ks.size, np.nan)
        _ck.scene_risks(
            np.ascontiguousarray(batch.cx[i, ks]), np.ascontiguousarray(batch.cy[i, ks]),
            np.ascontiguousarray(batch.cpsi[i, ks]), np.ascontiguousarray(cv[ks]),
            np.ascontiguousarray(dist), eng._za, eng._zw, eng._weight,
            0.5 * float(batch.c_length[i]), 0.5 * float(batch.c_width[i]),
            np.ascontiguousarray(x), zeros, zeros.copy(), np.ascontiguousarray(v),
            0.5 * batch.ego_length, 0.5 * batch.ego_width, man_a, man_w, rs.dt, rs.t_pnr,
            rs.t_max, rs.m, 2.0, out)
        prof[i, ks] = out
        peak[i] = float(np.max(out))
        above[i] = float(np.sum(out >= LEVEL)) * h
    return peak, peak.copy(), above, prof
