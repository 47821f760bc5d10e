"""The simulator's tabulated grid weights (``_grid_weights``: ``cutter_at``'s interval and
weight at the end of every step, read by ``run_builtin`` instead of dividing) against
``cutter_at`` itself, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from riskcore.sut import kernels as k


@pytest.mark.parametrize(("dt", "h", "m"), [(0.01, 0.1, 101), (0.01, 0.1, 551), (0.05, 0.1, 31),
                                            (0.01, 0.05, 40), (0.03, 0.1, 2)])
def test_grid_weights_are_cutter_at_s(dt: float, h: float, m: int) -> None:
    n_steps = 4000
    kk_at, f_at = k._grid_weights(n_steps, dt, h, m)
    rng = np.random.default_rng(1)
    row = rng.normal(size=(1, m))
    zero = np.zeros((1, m))
    for step in range(n_steps):
        t1 = (step + 1) * dt
        x = k.cutter_at(row, zero, zero, zero, zero, 0, h, t1)[0]
        if kk_at[step] < 0:
            assert t1 / h >= m - 1
            continue
        j = kk_at[step]
        f = f_at[step]
        assert 0 <= j <= m - 2
        assert x == row[0, j] * (1.0 - f) + row[0, j + 1] * f  # bit for bit
