"""The true-efficiency measure of benchmarks/bench_true_efficiency.py: exact cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm, truncnorm

from benchmarks.bench_true_efficiency import efficiency, read_hits


def test_a_constant_weight_gives_its_saving_by_hand() -> None:
    # every collided draw has w = p / q = 0.01 and P = 0.001:
    # saved = (1 - P) / (E[w] - P) = 0.999 / 0.009 = 111.0
    log_p = np.log(np.full(50, 0.02))
    log_q = np.log(np.full(50, 2.0))
    e = efficiency(log_p, log_q, 0.001)
    assert e["mean_w"] == pytest.approx(0.01)
    assert e["saved"] == pytest.approx(0.999 / 0.009)
    assert e["mean_w_lo"] == pytest.approx(0.01) and e["mean_w_hi"] == pytest.approx(0.01)
    assert e["top10_share"] == pytest.approx(10 / 50)


def test_a_shifted_normal_matches_its_closed_form() -> None:
    # p = N(0, 1), C = {x > c}, q = N(mu, 1): p^2 / q = phi(x + mu) exp(mu^2), so
    # E_{p|C}[p/q] = exp(mu^2) Q(c + mu) / Q(c) (Q the normal survival function)
    c, mu = 3.0, 3.2
    exact = math.exp(mu * mu) * norm.sf(c + mu) / norm.sf(c)
    rng = np.random.default_rng(4)
    x = truncnorm.rvs(c, np.inf, size=20_000, random_state=rng)
    e = efficiency(norm.logpdf(x), norm.logpdf(x, loc=mu), norm.sf(c), n_boot=500)
    assert e["mean_w_lo"] <= exact <= e["mean_w_hi"]
    assert e["mean_w"] == pytest.approx(exact, rel=0.05)
    # the optimum among shifts is far better than naive Monte Carlo (saved >> 1), and a
    # proposal that misses the set (mu = -1) is worse than naive (saved < 1)
    assert e["saved"] > 50
    bad = efficiency(norm.logpdf(x), norm.logpdf(x, loc=-1.0), norm.sf(c), n_boot=50)
    assert bad["saved"] < 1


def test_the_physical_share_enters_as_derived() -> None:
    # P(C | B) = 0.01, P(B) = 0.5, every E[w] = 0.0075: one draw's variance
    # P (E - P P(B)) / P(B) = 0.01 * 0.0025 / 0.5 = 5e-5, a naive run's 0.01 * 0.99
    # = 9.9e-3: 198 runs saved per draw
    e = efficiency(np.log(np.full(4, 0.0075)), np.zeros(4), 0.01, p_bounds=0.5, n_boot=10)
    assert e["saved"] == pytest.approx(198.0)


def test_hits_files_need_their_closing_line(tmp_path) -> None:
    f = tmp_path / "h.jsonl"
    f.write_text('{"z": [0.5, 1.0]}\n{"z": [0.25, 2.0]}\n{"runs": 1000, "collisions": 2}\n')
    z, hits, runs = read_hits([str(f)])
    assert z.shape == (2, 2) and hits == 2 and runs == 1000
    with pytest.raises(ValueError, match="no collided draws"):
        efficiency(np.zeros(0), np.zeros(0), 0.1)
