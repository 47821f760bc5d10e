"""Build -> ego-centric format -> datasets' extraction recovers the parameter vector.

Tolerances are the extraction's own (docs/datasets.md, "Tolerances"): gap 0.5 m,
dv 0.3 m/s, p_t 10 %, p_y1 5 % (and 0.003 rad/s), p_v0 0.2 m/s, p_a1 0.1 m/s^2 + 10 %,
p_a2 and p_a3 0.2 s.
"""

from __future__ import annotations

import pandas as pd
import pytest

from datasets.egocentric import scenario_to_egocentric
from datasets.extract import extract_egocentric
from sampler import build_scenario
from tests.sampler.factories import base_params

CASES = [
    base_params(),  # left-moving, no pulse, closing
    base_params(p_y1=-0.035, p_t=2.8, dv=-1.5, gap=20.0, p_v0=28.0),  # right-moving, opening
    base_params(p_a1=-1.2, p_a2=0.5, p_a3=2.0, dv=3.0, gap=8.0),  # braking pulse
    base_params(p_y1=-0.05, p_t=2.0, p_a1=0.8, p_a2=-0.5, p_a3=1.5, p_v0=22.0, dv=0.5,
                gap=15.0),  # accelerating, pulse starts before the lateral motion
]


@pytest.mark.parametrize("lane_width", [3.5, 3.75])
def test_build_then_extract_recovers_parameters(lane_width: float) -> None:
    frames = [scenario_to_egocentric(build_scenario(p, lane_width=lane_width), f"e{i}")
              for i, p in enumerate(CASES)]
    table = extract_egocentric(pd.concat(frames, ignore_index=True), source="built")
    assert list(table["event_id"]) == [f"e{i}" for i in range(len(CASES))]
    for i, p in enumerate(CASES):
        row = table.iloc[i]
        assert row["gap"] == pytest.approx(p["gap"], abs=0.5)
        assert row["dv"] == pytest.approx(p["dv"], abs=0.3)
        assert row["p_t"] == pytest.approx(p["p_t"], rel=0.10)
        assert row["p_y1"] == pytest.approx(p["p_y1"], rel=0.05, abs=0.003)
        assert row["p_v0"] == pytest.approx(p["p_v0"], abs=0.2)
        assert row["side"] == ("right" if p["p_y1"] > 0 else "left")
        assert row["lane_width"] == pytest.approx(lane_width)
        if p["p_a3"] > 0:
            assert row["p_a1"] == pytest.approx(p["p_a1"], abs=0.1 + 0.1 * abs(p["p_a1"]))
            assert row["p_a2"] == pytest.approx(p["p_a2"], abs=0.2)
            assert row["p_a3"] == pytest.approx(p["p_a3"], abs=0.2)
        else:
            # no pulse: whatever (p_a1, p_a3) the fit returns, the speed change is nil
            assert abs(row["p_a1"] * row["p_a3"]) < 0.2
