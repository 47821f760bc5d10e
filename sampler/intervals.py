"""Exact binomial intervals (Clopper-Pearson) used by the fit report and P(A), from
scipy's ``binomtest(k, n).proportion_ci(method="exact")``."""
from __future__ import annotations

from scipy.stats import binomtest

__all__ = ["clopper_pearson", "upper95", "upper_bound"]


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact two-sided binomial interval for k successes in n trials."""
    if n <= 0:
        return 0.0, 1.0
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


def upper_bound(k: int, n: int, confidence: float = 0.95) -> float:
    """One-sided upper bound of a binomial proportion (exact) at ``confidence``."""
    if n <= 0 or k >= n:
        return 1.0
    ci = binomtest(int(k), int(n), alternative="less").proportion_ci(
        confidence_level=confidence, method="exact")
    return float(ci.high)


def upper95(k: int, n: int) -> float:
    """One-sided 95 % upper bound of a binomial proportion (exact)."""
    return upper_bound(k, n, 0.95)
