"""The deterministic full-factorial input grid over ±3σ and its weights, eq. (4).

For each object the acceleration a and the turn rate ω take ``n_a`` and ``n_omega``
values, evenly spaced over mean ± k·std (k = ``sigma_range``, 3 in the paper):
z_i = k (2i - (n - 1)) / (n - 1), i = 0..n-1 (z = 0 when n = 1), a_i = μ_a + σ_a z_i.
The full factorial design pairs every a_i with every ω_j (N_smp = n_a · n_omega points,
index i · n_omega + j). Eq. (4) weighs each point by f_a(a_i) f_ω(ω_j) normalised over the
grid; because every a_i sits at z_i standard deviations, f_a(a_i) ∝ exp(-z_i²/2) / σ_a and
the factors 1/(σ√(2π)) cancel in the normalisation, so the weights depend on the grid
only: w_ij = exp(-z_i²/2) exp(-z_j²/2) / Σ.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from riskcore.errors import RiskcoreError

__all__ = ["input_grid", "standard_grid"]

FloatArray = NDArray[np.float64]


def standard_grid(n: int, sigma_range: float) -> FloatArray:
    """The n standard scores z_i, symmetric about 0 (exactly: z_{n-1-i} = -z_i).

    Returns
    -------
    ndarray of shape (n,)
    """
    if n < 1:
        raise RiskcoreError("standard_grid: n must be >= 1")
    if n == 1:
        return np.zeros(1)
    i = np.arange(n, dtype=np.float64)
    return sigma_range * (2.0 * i - (n - 1)) / (n - 1)


def input_grid(mean_a: float, std_a: float, mean_w: float, std_w: float, n_a: int,
               n_omega: int, sigma_range: float
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Inputs and unnormalised weights of the full-factorial grid.

    Parameters
    ----------
    mean_a, std_a : float
        μ_a, σ_a in m/s².
    mean_w, std_w : float
        μ_ω, σ_ω in rad/s.
    n_a, n_omega : int
    sigma_range : float

    Returns
    -------
    a, omega : ndarray of shape (n_a * n_omega,)
        m/s² and rad/s; point i·n_omega + j is (a_i, ω_j).
    weight : ndarray of shape (n_a * n_omega,)
        exp(-z_i²/2) exp(-z_j²/2), to be normalised by its sum (eq. 4).
    """
    za = standard_grid(n_a, sigma_range)
    zw = standard_grid(n_omega, sigma_range)
    a = np.repeat(mean_a + std_a * za, n_omega)
    w = np.tile(mean_w + std_w * zw, n_a)
    weight = np.outer(np.exp(-0.5 * za * za), np.exp(-0.5 * zw * zw)).ravel()
    return a, w, weight
