"""Settings of the risk engine: Table II of seed 000 and the ego's evasive capabilities."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from riskcore.errors import SettingsError

__all__ = ["RiskSettings"]

_MAX_STEPS = 1000


@dataclass(frozen=True)
class RiskSettings:
    """All parameters of one risk evaluation. Frozen; validated on construction.

    Table II of Wagner et al. (the defaults):

    Parameters
    ----------
    horizon : float
        Prediction horizon in s (3.0). Must be a whole number of ``dt`` steps.
    dt : float
        Prediction step in s (0.1).
    n_a, n_omega : int
        Grid points in acceleration and turn rate (10 × 10 = N_smp = 100).
    sigma_range : float
        The grid spans mean ± ``sigma_range`` · std in each input (3.0, "3σ-interval").
    t_pnr : float
        Point of no return T_PNR in s (0.5): TTR ≤ t_pnr weighs 1.
    t_max : float
        Maximum risk time T_max in s (2.0): TTR ≥ t_max weighs 0.
    m : float
        Steepness of the weighting g of eq. (5) (1.0); m = 0 is the linear ramp.

    The ego's capabilities for the evasive manoeuvres (not given by the paper; engineering
    defaults, sources in docs/riskcore.md):

    brake_max : float
        Full-braking deceleration in m/s² (8.0; dry asphalt, friction ≈ 0.8-0.9).
    accel_max : float
        Full-acceleration ("kick-down") in m/s² (2.0; typical car at highway speed).
    lat_accel_max : float
        Lateral-acceleration limit of full steering in m/s² (6.0). Full steering is the
        constant turn rate ω = min(lat_accel_max / v, v / min_turn_radius) at constant speed.
    min_turn_radius : float
        Smallest turning radius in m (5.5), bounds ω at low speed (ω → 0 as v → 0).
    """

    horizon: float = 3.0
    dt: float = 0.1
    n_a: int = 10
    n_omega: int = 10
    sigma_range: float = 3.0
    t_pnr: float = 0.5
    t_max: float = 2.0
    m: float = 1.0
    brake_max: float = 8.0
    accel_max: float = 2.0
    lat_accel_max: float = 6.0
    min_turn_radius: float = 5.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type in ("int", int):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise SettingsError(f"{f.name}: expected an integer, got {value!r}")
                if value < 1:
                    raise SettingsError(f"{f.name}: must be >= 1, got {value}")
            else:
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise SettingsError(f"{f.name}: expected a number, got {value!r}")
                if not math.isfinite(value):
                    raise SettingsError(f"{f.name}: must be finite, got {value!r}")
                object.__setattr__(self, f.name, float(value))
        positive = ("horizon", "dt", "sigma_range", "brake_max", "lat_accel_max",
                    "min_turn_radius")
        for name in positive:
            if getattr(self, name) <= 0:
                raise SettingsError(f"{name}: must be > 0, got {getattr(self, name)}")
        for name in ("t_pnr", "m", "accel_max"):
            if getattr(self, name) < 0:
                raise SettingsError(f"{name}: must be >= 0, got {getattr(self, name)}")
        if not self.t_pnr < self.t_max:
            raise SettingsError(f"t_pnr: must be < t_max ({self.t_pnr} >= {self.t_max})")
        steps = self.horizon / self.dt
        if abs(steps - round(steps)) > 1e-9 * max(1.0, steps) or round(steps) < 1:
            raise SettingsError(
                f"horizon: must be a whole number (>= 1) of dt steps, got {self.horizon} / "
                f"{self.dt} = {steps}")
        if round(steps) > _MAX_STEPS:  # the evasion buffer grows with the square of it
            raise SettingsError(f"horizon: at most {_MAX_STEPS} steps of dt, got "
                                f"{round(steps)}")

    @property
    def n_steps(self) -> int:
        """Number of prediction steps N; the grid has N + 1 times 0, dt, ..., N dt."""
        return round(self.horizon / self.dt)

    @property
    def n_samples(self) -> int:
        """N_smp = n_a · n_omega predicted trajectories per object."""
        return self.n_a * self.n_omega

    def replace(self, **changes: Any) -> RiskSettings:
        """A copy with some fields changed (validated). Unknown names are an error."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise SettingsError(f"unknown setting(s) {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float | int]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RiskSettings:
        """Build from a mapping of field names (missing ones take the defaults)."""
        if not isinstance(data, Mapping):
            raise SettingsError("settings: expected an object")
        return cls().replace(**dict(data))
