"""From TTRs to risk: the weighting g of eq. (5), r_k of eq. (6), r_dep (8) and r_ind (9)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore import kernels as _kernels
from riskcore.errors import RiskcoreError

__all__ = ["object_risk", "risk_dependent", "risk_independent", "ttr_weight"]

FloatArray = NDArray[np.float64]

def ttr_weight(ttr: ArrayLike, t_pnr: float = 0.5, t_max: float = 2.0,
               m: float = 1.0) -> FloatArray:
    """The TTR weighting g of eq. (5): 1 up to T_PNR, falling to 0 at T_max.

    g(TTR) = min(1, max(0, ḡ(TTR))) with, for m > 0,
    ḡ = (e^{-m(TTR - T_PNR)} - e^{-m(T_max - T_PNR)}) / (1 - e^{-m(T_max - T_PNR)})
      = expm1(m (T_max - TTR)) / expm1(m (T_max - T_PNR))   (the form computed)
    and for m = 0 the linear ramp ḡ = (T_max - TTR) / (T_max - T_PNR). TTR = +inf gives 0.
    g(T_PNR) = 1 and g(T_max) = 0 exactly.

    Parameters
    ----------
    ttr : array-like
        Times to react in s (>= 0, +inf allowed).
    t_pnr, t_max : float
        T_PNR < T_max in s.
    m : float
        Steepness (>= 0).

    Returns
    -------
    ndarray of the shape of ``ttr``
    """
    if not 0 <= t_pnr < t_max or m < 0:
        raise RiskcoreError("ttr_weight: need 0 <= t_pnr < t_max and m >= 0")
    x = np.asarray(ttr, dtype=np.float64)
    if np.isnan(x).any():
        raise RiskcoreError("ttr_weight: ttr must not be NaN")
    flat = np.ascontiguousarray(x).ravel()
    return _kernels.ttr_weight_many(flat, float(t_pnr), float(t_max), float(m)).reshape(x.shape)


def object_risk(weight: ArrayLike, g: ArrayLike) -> float:
    """r_k of eq. (6): Σ_i p_i g_i with p_i = weight_i / Σ weight.

    Computed as Σ w_i g_i / Σ w_i with both sums in the same order, so all g = 1 gives
    exactly 1.
    """
    w = np.asarray(weight, dtype=np.float64)
    gg = np.asarray(g, dtype=np.float64)
    if w.shape != gg.shape or w.ndim != 1 or w.shape[0] == 0:
        raise RiskcoreError("object_risk: weight and g must be 1-d of the same non-zero length")
    den = float(np.sum(w))
    if not den > 0:
        raise RiskcoreError("object_risk: weights must sum to > 0")
    return float(_kernels.weighted_mean(np.ascontiguousarray(w), np.ascontiguousarray(gg)))


def risk_independent(object_risks: Sequence[float] | ArrayLike) -> float:
    """r_ind of eq. (9): 1 - Π_k (1 - r_k); 0 for no objects."""
    r = np.asarray(object_risks, dtype=np.float64).ravel()
    return float(1.0 - np.prod(1.0 - r)) if r.size else 0.0


def risk_dependent(g: ArrayLike, p: ArrayLike) -> float:
    """r_dep of eq. (8), exactly, without enumerating the N_smp^N_TO outcomes.

    r_dep = Σ_s p_s g(min_k TTR_k,s) = E[max_k G_k], since g is non-increasing
    (g(min TTR) = max g), where G_k takes the value g_k,i with probability p_k,i,
    independently across objects. With F_k the CDF of G_k,
    E[max_k G_k] = ∫_0^{u_max} (1 - Π_k F_k(u)) du, a sum over the sorted values.
    Cost O(K·S·log(K·S)) for K objects with S samples each.

    Parameters
    ----------
    g : array-like of shape (K, S)
        Weights g(TTR) in [0, 1] of each object's samples.
    p : array-like of shape (K, S)
        Probabilities of each object's samples (rows sum to 1).

    Returns
    -------
    float
        r_dep in [0, 1]; 0 for K = 0.
    """
    gg = np.ascontiguousarray(g, dtype=np.float64)
    pp = np.ascontiguousarray(p, dtype=np.float64)
    if gg.ndim != 2 or gg.shape != pp.shape:
        raise RiskcoreError(f"risk_dependent: g and p must have the same shape (K, S), got "
                         f"{gg.shape} and {pp.shape}")
    if gg.shape[0] == 0:
        return 0.0
    if gg.shape[1] == 0 or not (np.isfinite(gg).all() and np.isfinite(pp).all()):
        raise RiskcoreError("risk_dependent: need S >= 1 and finite values")
    if (gg < 0).any() or (pp < 0).any():
        raise RiskcoreError("risk_dependent: g and p must be >= 0")
    return float(_kernels.expected_max(gg, pp))
