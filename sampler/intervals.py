"""Exact binomial intervals (Clopper-Pearson) used by the fit report and P(A), from
scipy's ``binomtest(k, n).proportion_ci(method="exact")``."""
from __future__ import annotations

from scipy.stats import binomtest

__all__ = ["clopper_pearson", "upper95"]


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact two-sided binomial interval for k successes in n trials."""
    if n <= 0:
        return 0.0, 1.0
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


def upper95(k: int, n: int) -> float:
    """One-sided 95 % upper bound of a binomial proportion (exact)."""
    if n <= 0 or k >= n:
        return 1.0
    ci = binomtest(int(k), int(n), alternative="less").proportion_ci(confidence_level=0.95,
                                                                     method="exact")
    return float(ci.high)
