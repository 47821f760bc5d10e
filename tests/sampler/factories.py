"""Seeded synthetic data for the sampler tests (no dependence on the embedded real data)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from datasets.cutin_model import PARAM_NAMES


def synthetic_parameter_table(n: int = 300, seed: int = 0,
                              no_pulse_share: float = 1.0 / 3.0) -> pd.DataFrame:
    """A plausible cut-in parameter table: columns PARAM_NAMES, SI units.

    Lateral displacement around 3.6 m (so every row crosses a 3.75 m lane's marking),
    ``no_pulse_share`` of the rows without an acceleration pulse (p_a3 = 0 exactly, as in
    real data; such a spike becomes a needle-thin mixture component),
    mostly non-closing cut-ins (dv < 0) with a closing tail.
    """
    rng = np.random.default_rng(seed)
    side = rng.choice([-1.0, 1.0], size=n, p=[0.4, 0.6])
    p_v0 = np.clip(rng.normal(24.0, 4.0, n), 8.0, 40.0)
    p_t = np.exp(rng.normal(np.log(2.5), 0.25, n))
    disp = rng.normal(3.7, 0.25, n)
    p_y1 = side * disp * np.pi / (2.0 * p_v0 * p_t**2)
    has_pulse = rng.random(n) >= no_pulse_share
    p_a1 = np.where(has_pulse, rng.normal(0.0, 0.6, n), 0.0)
    p_a2 = rng.normal(1.0, 1.0, n)
    p_a3 = np.where(has_pulse, np.exp(rng.normal(0.3, 0.5, n)), 0.0)
    dv = rng.normal(-1.5, 2.0, n)
    gap = np.exp(rng.normal(np.log(18.0), 0.5, n))
    table = pd.DataFrame(dict(zip(PARAM_NAMES, [p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap],
                                  strict=True)))
    table["side"] = np.where(side > 0, "right", "left")
    return table


def base_params(**overrides: float) -> dict[str, float]:
    """One hand-checkable parameter vector (no pulse, 25 m/s, closing at 2 m/s, 12 m gap)."""
    p = {"p_y1": 0.04, "p_t": 2.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0, "p_v0": 25.0,
         "dv": 2.0, "gap": 12.0}
    p.update(overrides)
    return p


# A known mixture of (gap, dv) that the bootstrap-coverage test and benchmark draw their data
# sets from: P(gap < c) under it and under any fitted mixture are closed forms.
TRUE_W = np.array([0.6, 0.4])
TRUE_MU = np.array([[30.0, -1.0], [16.0, 2.0]])
TRUE_SD = np.array([[6.0, 1.5], [4.0, 1.0]])


def true_p(cut: float) -> float:
    """P(gap < cut) under the known mixture."""
    return float(sum(w * stats.norm.cdf((cut - m[0]) / s[0])
                     for w, m, s in zip(TRUE_W, TRUE_MU, TRUE_SD, strict=True)))


def draw_table(n: int, rng: np.random.Generator) -> pd.DataFrame:
    """n rows (gap, dv) drawn from the known mixture."""
    lab = rng.random(n) < TRUE_W[1]
    mu, sd = TRUE_MU[lab.astype(int)], TRUE_SD[lab.astype(int)]
    x = mu + sd * rng.standard_normal((n, 2))
    return pd.DataFrame({"gap": x[:, 0], "dv": x[:, 1]})


def closed_form(weights: Any, means: Any, covs: Any, z_cut: float) -> float:
    """P(z_gap < z_cut) of a mixture in z (gap is feature 0): a half-space."""
    return float(sum(w * stats.norm.cdf((z_cut - m[0]) / math.sqrt(c[0][0]))
                     for w, m, c in zip(weights, means, covs, strict=True)))


def assert_band_density(model: Any, part: Any, zq: np.ndarray, n: int,
                        rng: np.random.Generator) -> None:
    """A band part's density is normalised and its weights average to the band's mass.

    ``zq``: ``part``'s own draws. With ``n`` model draws added (from ``rng``), the ratio
    ``q / r`` under the equal mixture ``r = (p + q) / 2`` has mean 1 (q integrates to 1),
    and ``p / q`` over the part's draws has mean P(band) as 400,000 model draws count it."""
    z = np.concatenate([model.sample_z(n, rng), zq])
    log_p = model.log_density_z(z)
    log_q = part.log_q(z)
    assert np.isfinite(log_q[n:]).all()
    log_r = np.logaddexp(log_p, log_q) - math.log(2)
    ratio = np.exp(log_q - log_r)
    se = ratio.std(ddof=1) / math.sqrt(ratio.size)
    assert abs(ratio.mean() - 1.0) <= 4 * se and se < 0.005
    w = np.exp(log_p[n:] - log_q[n:])
    zb = model.sample_z(400_000, np.random.default_rng(6))
    lo_b, hi_b = part.band(zb)
    on_b = (zb[:, part.law.j] > lo_b) & (zb[:, part.law.j] < hi_b)
    p_band = on_b.mean()
    se_b = math.sqrt(p_band * (1 - p_band) / on_b.size)
    se_w = w.std(ddof=1) / math.sqrt(w.size)
    assert abs(w.mean() - p_band) <= 4 * math.hypot(se_b, se_w)
