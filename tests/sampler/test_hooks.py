"""sample() asks the strategy through its hooks and never checks its type (issue 26 item 2):
a sampler of the caller's own gets the pilot it plans, its prepare step, its own P(A) and
its own summary line; a known P(A) is passed as data."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from sampler.methods.probability import PRegion
from sampler.methods.problem import Draw, Pilot, PilotPlan, Problem, ProgressFn, Run, Sampler
from sampler.methods.samplers import RejectionSampler
from sampler.model.gmm import CutInGMM
from sampler.sampling import sample
from tests.sampler.factories import synthetic_parameter_table

FIXED = PRegion(estimate=0.25, ci_low=0.2, ci_high=0.3, confidence=0.95, method="mine",
                n_draws=100, n_hits=25, p_bounds=0.9, p_bounds_ci=(0.85, 0.95), p_joint=0.225)


@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=0))


class Recording(Sampler):
    """Rejection's draws, with every hook recorded and answered by hand."""

    name = "recording"

    def __init__(self) -> None:
        self.calls: list[str] = []
        self._inner = RejectionSampler()

    def pilot_plan(self, problem: Problem) -> PilotPlan:
        self.calls.append("pilot_plan")
        return PilotPlan(need=7)

    def prepare(self, run: Run, n: int, pilot: Pilot) -> None:
        self.calls.append(f"prepare n={n} hits>={min(pilot.n_hits, 7)}")

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        self.calls.append("draw")
        out = self._inner.draw(problem, n, rng, pilot, progress)
        out.method = self.name
        return out

    def estimate_p(self, run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
        self.calls.append("estimate_p")
        return FIXED

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        return ["my own line"]

    def settings(self) -> dict[str, Any]:
        return {"name": self.name}


def test_sample_asks_the_hooks_in_order(model: CutInGMM) -> None:
    strategy = Recording()
    ss = sample(model, ["ttc<8"], 20, seed=1, method=strategy)
    assert strategy.calls == ["pilot_plan", "prepare n=20 hits>=7", "draw", "estimate_p"]
    assert ss.p_region == FIXED and ss.method == "recording"
    np.testing.assert_allclose(ss.exposure_weights, np.full(20, 0.25 / 20))
    # a method that is not in SAMPLERS gets the base summary (its ESS), not rejection's
    assert ss.summary().endswith(f"ESS {ss.diagnostics['ess']:.0f}")


def test_a_known_region_is_not_estimated(model: CutInGMM) -> None:
    strategy = Recording()
    ss = sample(model, ["ttc<8"], 20, seed=1, method=strategy, known_region=FIXED)
    assert "estimate_p" not in strategy.calls and ss.p_region == FIXED
    assert ss.sampler_settings["known_region"]["method"] == "mine"
    # P(B) is not estimated: the generator does not advance by its n_bounds draws, so
    # the samples differ from the same seed's without the known P(A)
    plain = sample(model, ["ttc<8"], 20, seed=1, method=Recording())
    assert not np.array_equal(ss.params.to_numpy(), plain.params.to_numpy())
