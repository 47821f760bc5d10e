"""The regulation's must-avoid threshold against its published tables, by hand."""

from __future__ import annotations

import numpy as np
import pytest

from riskcore.sut import SutError, must_avoid, must_avoid_ttc

KMH = 1 / 3.6


@pytest.mark.parametrize(("kmh", "table"), [(10, 0.48), (20, 0.71), (30, 0.94), (40, 1.18),
                                           (50, 1.41), (60, 1.64)])
def test_6_ms2_table(kmh: float, table: float) -> None:
    # by hand: v / 12 + 0.1 + 6 / 40, e.g. 10 km/h: 2.7778 / 12 + 0.25 = 0.4815 -> 0.48
    assert round(float(must_avoid_ttc(kmh * KMH, "6")), 2) == table


@pytest.mark.parametrize(("kmh", "table"), [(10, 0.74), (20, 1.32), (30, 1.90), (40, 2.47),
                                           (50, 3.05), (60, 3.63)])
def test_2_4_ms2_table(kmh: float, table: float) -> None:
    assert round(float(must_avoid_ttc(kmh * KMH, "2.4")), 2) == table


def test_verdict() -> None:
    v = np.array([20 * KMH, 20 * KMH, 20 * KMH, 5.0, 5.0])
    ttc = np.array([0.70, 0.72, np.nan, np.inf, 0.1])
    assert list(must_avoid(ttc, v)) == [False, True, False, True, False]
    with pytest.raises(SutError, match="variant"):
        must_avoid(ttc, v, "7")
