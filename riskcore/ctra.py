"""CTRA motion model of eq. (1): constant turn rate ω and constant acceleration a.

    ẋ = v cos ψ,  ẏ = v sin ψ,  ψ̇ = ω,  v̇ = a

For constant inputs the solution is closed-form and exact (no integration error). With
φ = ω τ and the integrals S0, C0, S1, C1 over u ∈ [0, 1] of cos(φu), sin(φu), u cos(φu),
u sin(φu)::

    ψ(τ) = ψ0 + φ,   v(τ) = v0 + a τ
    L = v0 τ S0 + a τ² S1     (displacement along the initial heading)
    S = v0 τ C0 + a τ² C1     (displacement to the left of it)
    x(τ) = x0 + L cos ψ0 - S sin ψ0,   y(τ) = y0 + L sin ψ0 + S cos ψ0

The ω → 0 limit (S0 = 1, C0 = 0, S1 = 1/2, C1 = 0: straight line with constant
acceleration) is reached smoothly: for |φ| < 0.1 the integrals are evaluated from their
Taylor series, so no 1/ω or 1/ω² cancellation occurs. Vehicles do not reverse: with
a < 0 the motion stops at v = 0 (τ_s = v0 / -a) and the state stays frozen after that; a
vehicle at standstill with a ≤ 0 does not turn on the spot.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore import kernels as _kernels
from riskcore.errors import RiskcoreError

__all__ = ["ctra_states"]

FloatArray = NDArray[np.float64]


def ctra_states(x0: ArrayLike, y0: ArrayLike, psi0: ArrayLike, v0: ArrayLike, a: ArrayLike,
                omega: ArrayLike, tau: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """States after ``tau`` seconds of constant inputs, exactly (broadcasting arrays).

    Parameters
    ----------
    x0, y0 : array-like
        Initial centre position in m.
    psi0 : array-like
        Initial heading in rad (counter-clockwise from +x).
    v0 : array-like
        Initial speed in m/s (>= 0).
    a : array-like
        Acceleration along the heading in m/s².
    omega : array-like
        Turn rate in rad/s.
    tau : array-like
        Elapsed time in s (>= 0).

    Returns
    -------
    x, y, psi, v : ndarray of the broadcast shape
        Position (m), heading (rad), speed (m/s).
    """
    arrays = np.broadcast_arrays(*(np.asarray(q, dtype=np.float64)
                                   for q in (x0, y0, psi0, v0, a, omega, tau)))
    shape = arrays[0].shape
    flat = [np.ascontiguousarray(q).ravel() for q in arrays]
    if not all(np.isfinite(q).all() for q in flat):
        raise RiskcoreError("ctra_states: inputs must be finite")
    if (flat[3] < 0).any() or (flat[6] < 0).any():
        raise RiskcoreError("ctra_states: v0 and tau must be >= 0")
    out = np.empty((flat[0].shape[0], 4))
    _kernels.ctra_many(flat[0], flat[1], flat[2], flat[3], flat[4], flat[5], flat[6], out)
    return (out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape),
            out[:, 3].reshape(shape))
