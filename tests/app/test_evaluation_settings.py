"""Issue 24 item 1: the simulator settings a request or `scengen evaluate --setting` gives
(sensor range, perception delay, update period) reach the simulator that drives the SUT:
the service's runner (both entry points build it with ``runner_for``) gives the outcomes of
``sampler.campaign.sut_runner`` with those ``SimSettings``, which differ from the defaults'."""

from __future__ import annotations

import numpy as np
import pytest

from app.services import evaluations as service
from app.services import suts
from datasets import PARAM_NAMES
from riskcore.sut import SimSettings
from sampler.campaign import sut_runner

# closing cut-ins (p_y1, p_t, p_a1, p_a2, p_a3, p_v0, dv, gap): the cutter 8-30 m ahead,
# 4-8 m/s slower than the ego
VECTORS = [
    {"p_y1": 0.1, "p_t": 2.0, "p_a1": 0.0, "p_a2": 0.5, "p_a3": 1.0, "p_v0": 25.0,
     "dv": 6.0, "gap": 20.0},
    {"p_y1": -0.12, "p_t": 2.5, "p_a1": -1.0, "p_a2": 0.0, "p_a3": 2.0, "p_v0": 30.0,
     "dv": 8.0, "gap": 30.0},
    {"p_y1": 0.08, "p_t": 1.8, "p_a1": 0.5, "p_a2": 1.0, "p_a3": 0.5, "p_v0": 20.0,
     "dv": 4.0, "gap": 8.0},
]


@pytest.mark.parametrize("settings", [
    {"sensor_range": 12.0},
    {"perception_delay": 0.5},
    {"update_period": 0.5},
])
def test_request_settings_reach_the_simulator(settings: dict[str, float]) -> None:
    params = np.array([[v[k] for k in PARAM_NAMES] for v in VECTORS])
    seeds = np.arange(len(VECTORS), dtype=np.uint64)
    factory = suts.resolve("acc", allow_import=False).factory({})
    got = service.runner_for(None, factory, settings)(params, seeds)
    want = sut_runner(factory, settings=SimSettings(**settings), careful=True)(params, seeds)
    default = service.runner_for(None, factory, None)(params, seeds)
    for key in ("collided", "impact_speed", "min_gap", "t_brake_rel_tp", "careful_collided"):
        np.testing.assert_array_equal(got.arrays[key], want.arrays[key], key)
    assert not np.array_equal(got.arrays["min_gap"], default.arrays["min_gap"])
