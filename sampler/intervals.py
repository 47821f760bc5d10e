"""Exact binomial intervals (Clopper-Pearson) used by the fit report and P(A)."""
from __future__ import annotations

from scipy import stats

__all__ = ["clopper_pearson", "upper95"]


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact two-sided binomial interval for k successes in n trials."""
    if n <= 0:
        return 0.0, 1.0
    alpha = 1.0 - confidence
    lo = 0.0 if k == 0 else float(stats.beta.ppf(alpha / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
    return lo, hi


def upper95(k: int, n: int) -> float:
    """One-sided 95 % upper bound of a binomial proportion (exact)."""
    if n <= 0:
        return 1.0
    if k >= n:
        return 1.0
    return float(stats.beta.ppf(0.95, k + 1, n - k))

