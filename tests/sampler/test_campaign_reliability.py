"""The verdict on a campaign's figures (``sampler.campaign.reliability``): hand-made
summaries for each warning, and the summary of real (stand-in) campaigns carrying it."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from sampler import CutInGMM
from sampler.campaign import StandInRuns, evaluate, halfspace_runner
from sampler.campaign.reliability import (
    assess,
    interval_reasons,
    verdict,
    warnings,
    with_verdict,
)
from tests.sampler.factories import synthetic_parameter_table

#: a campaign whose figures are to be trusted: the stop rule met, enough of everything
GOOD: dict[str, Any] = {
    "p_collision": {"estimate": 1.3e-5, "ci": [1.0e-5, 1.7e-5], "rhw": 0.25,
                    "upper_bound": None, "hits": 82, "ess": 30.5},
    "runs": 6000, "sut_runs": 4200, "pilot_runs": 0, "adapt": "kernels",
    "collisions": 82, "ess": 30.5, "acceleration": 250.0, "stop_reason": "rhw",
    "confidence": 0.95, "rhw_target": 0.3,
}


def _with(**changes: Any) -> dict[str, Any]:
    out = dict(GOOD)
    out.update(changes)
    return out


def _codes(summary: dict[str, Any]) -> list[str]:
    return [f.code for f in assess(summary)]


def test_a_campaign_that_met_the_stop_rule_is_reliable() -> None:
    assert assess(GOOD) == []
    assert verdict(GOOD) == {"warnings": [], "reliable": True}
    # exactly on the thresholds (10 collisions, ESS 10): trusted
    assert _codes(_with(collisions=10, ess=10.0)) == []


def test_fewer_than_ten_collisions() -> None:
    s = _with(collisions=9, ess=40.0)
    assert _codes(s) == ["few_collisions"]
    (text,) = warnings(s)
    assert text.startswith("only 9 collisions (fewer than 10)")
    assert "run more" in text
    assert verdict(s) == {"warnings": [text], "reliable": False}
    # one collision: singular, and its ESS is 1 too
    one = _with(collisions=1, ess=1.0)
    assert _codes(one) == ["few_collisions", "low_ess"]
    assert warnings(one)[0].startswith("only 1 collision (")


@pytest.mark.parametrize(("ess", "shown"), [(1.56, "1.56"), (9.99, "9.99"),
                                            (None, "undefined"), ("nan", "undefined")])
def test_a_small_effective_sample_size(ess: Any, shown: str) -> None:
    s = _with(collisions=300, ess=ess)
    assert _codes(s) == ["low_ess"]
    assert warnings(s)[0].startswith(f"effective sample size (ESS) {shown}, below 10")


def test_no_collision_gives_only_an_upper_bound() -> None:
    s = _with(collisions=0, ess=0.0, stop_reason="n", rhw_target=None,
              p_collision={"estimate": 0.0, "ci": [None, None], "rhw": None,
                           "upper_bound": 0.0029957, "hits": 0, "ess": 0.0}, runs=1000)
    assert _codes(s) == ["no_collision"]  # an ESS of 0 is not flagged besides
    (text,) = warnings(s)
    assert text.startswith("no collision in 1000 draws")
    assert "upper bound 0.003 per cut-in" in text and "95 %" in text


def test_stopped_at_max_runs_before_the_stop_rule() -> None:
    s = _with(stop_reason="max_runs", runs=200_000,
              p_collision={**GOOD["p_collision"], "rhw": 0.4512})
    assert _codes(s) == ["max_runs"]
    (text,) = warnings(s)
    assert text.startswith("stopped at max_runs (200000 draws) before the stop rule")
    assert "at most 0.3" in text and "relative half-width 0.45" in text
    # with -n there is no stop rule: ending at n is no finding
    assert _codes(_with(stop_reason="n", rhw_target=None)) == []


def test_max_runs_without_any_collision_says_both() -> None:
    s = _with(stop_reason="max_runs", collisions=0, ess=0.0,
              p_collision={"rhw": None, "upper_bound": 1e-6, "hits": 0})
    assert _codes(s) == ["no_collision", "max_runs"]
    assert "no relative half-width (no collision)" in warnings(s)[1]


def test_a_cross_entropy_campaign_without_its_final_stage() -> None:
    s = _with(adapt="ce", pilot_runs=0, runs=1500)
    assert _codes(s) == ["ce_no_final_stage"]
    assert warnings(s)[0].startswith("adapt=ce: the campaign ended before its final stage")
    # with pilot chunks left out, the final stage was reached
    assert _codes(_with(adapt="ce", pilot_runs=2000, runs=3000)) == []
    # the kernels' campaigns have no pilot chunks at all
    assert _codes(_with(adapt="kernels", pilot_runs=0)) == []
    # one chunk: the defensive mixture only, as a kernels campaign's first chunk (the
    # dashboard's and the README's 2,000 draws in one chunk of 2,000)
    assert _codes(_with(adapt="ce", pilot_runs=0, runs=2000, chunks=1)) == []
    assert _codes(_with(adapt="ce", pilot_runs=0, runs=4000, chunks=2)) == [
        "ce_no_final_stage"]
    # without any collision "no collision" says it all (the default adapt is ce)
    assert _codes(_with(adapt="ce", pilot_runs=0, runs=1500, collisions=0,
                        p_collision={"rhw": None, "upper_bound": 2e-3, "hits": 0})) == [
        "no_collision"]


def test_every_warning_at_once_in_a_fixed_order() -> None:
    s = _with(collisions=3, ess=2.0, stop_reason="max_runs", adapt="ce", pilot_runs=0,
              p_collision={"rhw": 1.7, "upper_bound": None, "hits": 3})
    assert _codes(s) == ["few_collisions", "low_ess", "max_runs", "ce_no_final_stage"]


def test_an_older_summary_without_the_newer_fields() -> None:
    """A summary stored before ``adapt``, ``pilot_runs`` and the verdict existed: read
    with the same rule, no finding from the missing fields."""
    old = {k: v for k, v in GOOD.items() if k not in ("adapt", "pilot_runs")}
    assert with_verdict(old) == {**old, "warnings": [], "reliable": True}
    few = with_verdict({**old, "collisions": 4, "ess": 3.2})
    assert few["reliable"] is False and len(few["warnings"]) == 2
    # a stale verdict is replaced by the rule's
    assert with_verdict({**old, "warnings": ["stale"], "reliable": False})["reliable"] is True


@pytest.mark.parametrize(("collisions", "ess", "short"), [
    (0, 0.0, []), (82, 30.5, []), (10, 10.0, []), (9, 40.0, ["only 9 collisions"]),
    (1, 1.0, ["only 1 collision", "ESS 1"]), (300, 1.56, ["ESS 1.56"]),
    (50, None, ["ESS undefined"]), (None, None, [])])
def test_the_dashboards_short_reasons(collisions: Any, ess: Any, short: list[str]) -> None:
    assert interval_reasons(collisions, ess) == short


# --------------------------------------------------------------------------- campaigns
@pytest.fixture(scope="module")
def model() -> CutInGMM:
    return CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(
        synthetic_parameter_table(300, seed=3))


def _never(params: np.ndarray, seeds: np.ndarray) -> StandInRuns:
    n = params.shape[0]
    return StandInRuns(np.zeros(n, dtype=bool), np.zeros(n), np.zeros(n, dtype=bool),
                       np.zeros(n, dtype=bool))


def test_a_campaign_without_collision_stopped_at_max_runs_says_so(model: CutInGMM) -> None:
    r = evaluate(model, _never, rhw=0.3, max_runs=600, seed=0, batch_size=300,
                 physical_bounds=False, bootstrap=False)
    s = r.summary()
    assert s["collisions"] == 0 and s["stop_reason"] == "max_runs"
    assert s["reliable"] is False
    assert [w.split(" ")[0] for w in s["warnings"]] == ["no", "stopped"]
    assert s["warnings"][0].startswith("no collision in 600 draws")
    assert s["warnings"][1].startswith("stopped at max_runs (600 draws)")


def test_a_campaign_with_many_collisions_is_reliable(model: CutInGMM) -> None:
    a = np.zeros(model.n_features)
    a[model.features_.index("dv")] = -1.0
    # z_dv >= 0 (about half the model): 600 draws hold hundreds of collided runs
    r = evaluate(model, halfspace_runner(model, a, 0.0),
                 n=600, seed=2, batch_size=300, physical_bounds=False, bootstrap=False)
    s = r.summary()
    assert s["collisions"] >= 10 and s["ess"] >= 10
    assert s["warnings"] == [] and s["reliable"] is True


def test_a_short_cross_entropy_campaign_warns_that_every_chunk_counted(
        model: CutInGMM) -> None:
    a = np.zeros(model.n_features)
    a[model.features_.index("gap")] = 1.0
    # a final stage that needs far more collided runs than 600 draws can give
    r = evaluate(model, halfspace_runner(model, a, 0.0),
                 n=600, seed=1, batch_size=300, physical_bounds=False, bootstrap=False,
                 adapt="ce", ce_min_hits=10_000)
    assert not any(c.counted for c in r.chunks)  # no final chunk: all of them count
    s = r.summary()
    assert s["pilot_runs"] == 0 and s["adapt"] == "ce"
    assert s["reliable"] is False
    assert any(w.startswith("adapt=ce: the campaign ended before its final stage")
               for w in s["warnings"])
    assert math.isfinite(s["p_collision"]["estimate"])
