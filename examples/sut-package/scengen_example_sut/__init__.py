"""Two small systems under test for scengen (issue 24), registered under the entry-point
group ``scengen.suts`` by this package's pyproject.toml.

``GapKeeper`` is batched (``riskcore.sut.SystemUnderTest``): ``reset(n, seeds)`` and
``act(obs)`` on arrays of N runs at once, as fast as numpy. ``LateBraker`` is per run
(``riskcore.sut.PerRunSUT``): ``reset(seed)`` and ``act(obs)`` for one run, the simplest to
write; scengen wraps it (``riskcore.sut.per_run``) and calls it once per run and step.

Both return the ego's longitudinal acceleration command in m/s² (negative: braking); the
simulator clips it to its limits (``SimSettings``: a_brake_max, a_accel_max, jerk_max).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

__all__ = ["GapKeeper", "LateBraker"]


class GapKeeper:
    """Brakes in proportion to how far the gap to the vehicle ahead in the ego's lane is
    below a time gap; holds its speed otherwise."""

    #: shown by ``scengen evaluate --list-suts`` and ``GET /suts``: value, unit, meaning
    parameters: ClassVar[dict[str, tuple[float, str, str]]] = {
        "time_gap": (1.0, "s", "the gap it keeps, in seconds of its speed"),
        "gain": (0.8, "1/s²", "deceleration per metre of missing gap"),
        "a_min": (-8.0, "m/s²", "its strongest braking")}
    source = "scengen examples/sut-package (a toy, not a real ADS)"

    def __init__(self, time_gap: float = 1.0, gain: float = 0.8, a_min: float = -8.0) -> None:
        if not (time_gap > 0 and gain > 0 and a_min < 0):
            raise ValueError("time_gap > 0 s, gain > 0 and a_min < 0 m/s² please")
        self.name = "example_gap_keeper"
        self.time_gap, self.gain, self.a_min = float(time_gap), float(gain), float(a_min)

    def reset(self, n: int, seeds: np.ndarray) -> None:
        self.n = n  # deterministic: the seeds are not needed

    def act(self, obs: Any) -> np.ndarray:  # obs: riskcore.sut.Observations
        ahead = obs.present & (obs.lane == 0) & (obs.gap > -0.5 * obs.length)
        gap = np.where(ahead, obs.gap, np.inf).min(axis=1)  # (N,) nearest in the lane
        missing = obs.ego_v * self.time_gap - gap
        cmd = np.where(missing > 0, -self.gain * missing, 0.0)
        return np.maximum(cmd, self.a_min)


class LateBraker:
    """Brakes hard once the cutter is in its lane and its time to collision is short, after
    a reaction time drawn from the run's seed (0.5-1.5 s): a driver who was not looking."""

    parameters: ClassVar[dict[str, tuple[float, str, str]]] = {
        "ttc_brake": (2.0, "s", "brakes when the TTC falls below this"),
        "decel": (6.0, "m/s²", "its braking")}
    source = "scengen examples/sut-package (a toy, not a real ADS)"

    def __init__(self, ttc_brake: float = 2.0, decel: float = 6.0) -> None:
        self.ttc_brake, self.decel = float(ttc_brake), float(decel)

    def reset(self, seed: int) -> None:
        self.reaction = float(np.random.default_rng(seed).uniform(0.5, 1.5))
        self.seen_at: float | None = None

    def act(self, obs: Any) -> float:  # obs: riskcore.sut.Observation
        closing = obs.v[0] < obs.ego_v
        in_lane = bool(obs.present[0]) and int(obs.lane[0]) == 0 and obs.gap[0] > 0
        ttc = obs.gap[0] / (obs.ego_v - obs.v[0]) if closing and in_lane else np.inf
        if ttc < self.ttc_brake and self.seen_at is None:
            self.seen_at = obs.t
        if self.seen_at is not None and obs.t >= self.seen_at + self.reaction:
            return -self.decel
        return 0.0
