"""Settings of the closed-loop simulator (:class:`SimSettings`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from riskcore.sut.errors import SutError

__all__ = ["SimSettings"]


@dataclass(frozen=True)
class SimSettings:
    """The simulator's step, the ego's limits and the SUT's perception. Frozen, validated.

    dt : float
        Simulation step, s (0.01: the criticality record's step). Contact is refined
        between steps to floating-point resolution.
    a_brake_max : float
        Largest deceleration the ego's brakes give, m/s² (> 0; 9.0, about 0.9 g on a dry
        road). A stronger command is clipped to it.
    a_accel_max : float
        Largest acceleration, m/s² (3.0).
    jerk_max : float
        The ego's actual acceleration moves towards the command at most this fast, m/s³
        (12.65: UN R157's careful driver reaches 0.774 g in 0.6 s, so the reference
        drivers brake exactly as in the criticality record). A step command of a full
        brake therefore ramps up over ``a / jerk_max``.
    perception_delay : float
        The objects' fields of the observations are those of this long ago, s (0).
    update_period : float
        The SUT is asked every this long and its command held in between, s (None: every
        step). A whole number of steps.
    sensor_range : float
        An object is present when its centre is within this distance of the ego's, m (200).
    t_max : float
        A run that has not resolved by then ends, s of scenario time (120).
    brake_threshold : float
        The ego "brakes" (``t_brake_rel_tp``) once its command is at most
        ``-brake_threshold``, m/s² (0.5).
    """

    dt: float = 0.01
    a_brake_max: float = 9.0
    a_accel_max: float = 3.0
    jerk_max: float = 12.65
    perception_delay: float = 0.0
    update_period: float | None = None
    sensor_range: float = 200.0
    t_max: float = 120.0
    brake_threshold: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "update_period" and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise SutError(f"{f.name}: expected a number, got {value!r}")
            if not (math.isfinite(value) and value >= 0):
                raise SutError(f"{f.name}: must be a finite number >= 0, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        for name in ("dt", "a_brake_max", "jerk_max", "sensor_range", "t_max"):
            if not getattr(self, name) > 0:
                raise SutError(f"{name}: must be > 0, got {getattr(self, name)}")
        if self.dt > 0.1:
            raise SutError(f"dt: at most 0.1 s, got {self.dt}")
        if self.update_period is not None:
            k = self.update_period / self.dt
            if self.update_period <= 0 or abs(k - round(k)) > 1e-6:
                raise SutError(f"update_period: must be a positive whole number of steps "
                               f"of dt = {self.dt} s, got {self.update_period}")
        k = self.perception_delay / self.dt
        if abs(k - round(k)) > 1e-6:
            raise SutError(f"perception_delay: must be a whole number of steps of dt = "
                           f"{self.dt} s, got {self.perception_delay}")

    @property
    def update_steps(self) -> int:
        """The SUT is asked every this many steps."""
        return 1 if self.update_period is None else max(1, round(self.update_period / self.dt))

    @property
    def delay_steps(self) -> int:
        return round(self.perception_delay / self.dt)

    def replace(self, **changes: Any) -> SimSettings:
        """A copy with some fields changed (validated). Unknown names are an error."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise SutError(f"unknown simulator setting(s) {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float | None]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SimSettings:
        """Settings from a mapping of field names (missing ones take the defaults)."""
        if not isinstance(data, Mapping):
            raise SutError("settings: expected an object")
        return cls().replace(**dict(data))
