"""sampler.intervals: the project's one source of exact binomial bounds."""

from __future__ import annotations

import pytest

from sampler.intervals import clopper_pearson, upper95, upper_bound


@pytest.mark.parametrize("n", [1, 7, 100, 4096])
@pytest.mark.parametrize("confidence", [0.9, 0.95, 0.99])
def test_upper_bound_of_no_hits_is_the_closed_form(n: int, confidence: float) -> None:
    # k = 0: P(X = 0) = (1 - p)^n = 1 - confidence  =>  p = 1 - (1 - confidence)^(1/n)
    assert upper_bound(0, n, confidence) == pytest.approx(1 - (1 - confidence) ** (1 / n),
                                                          rel=1e-9)


def test_upper_bound_hand_cases() -> None:
    # n = 1, k = 0: P(X = 0) = 1 - p = 0.05  =>  p = 0.95
    assert upper_bound(0, 1, 0.95) == pytest.approx(0.95)
    assert upper95(0, 20) == pytest.approx(1 - 0.05 ** (1 / 20))
    assert upper_bound(3, 3) == 1.0
    assert upper_bound(0, 0) == 1.0


def test_two_sided_interval_hand_case() -> None:
    # k = 0: the lower end is 0 and the upper is the one-sided bound at (1 + c) / 2
    lo, hi = clopper_pearson(0, 10, 0.95)
    assert lo == 0.0
    assert hi == pytest.approx(1 - 0.025 ** (1 / 10))
