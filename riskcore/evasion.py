"""The ego's evasive manoeuvres for the time-to-react (TTR) scan: strategy objects.

From reaction step j the ego leaves its known trajectory and applies one manoeuvre with
constant inputs (a, ω) of the CTRA model for the rest of the horizon. A manoeuvre only
says which inputs it applies at the ego's speed v; the engine does the rest.

- ``steer_left`` / ``steer_right`` (TTS): constant speed, turn rate
  ω = ±min(a_lat,max / v, v / R_min) (lateral acceleration v·ω = a_lat,max, bounded by the
  smallest turning radius at low speed; ω = 0 at standstill).
- ``brake`` (TTB): a = -brake_max, ω = 0, until standstill.
- ``accelerate`` (TTK, "kick-down"): a = +accel_max, ω = 0.

The order of :data:`MANOEUVRES` fixes the bits of the evasion masks: bit m (value 2**m)
stands for ``MANOEUVRES[m]``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import NDArray

from riskcore.errors import RiskcoreError
from riskcore.settings import RiskSettings

__all__ = ["MANOEUVRES", "Accelerate", "Brake", "Manoeuvre", "Steer", "evasion_label",
           "evasion_names"]

FloatArray = NDArray[np.float64]


class Manoeuvre(ABC):
    """One evasive manoeuvre: constant CTRA inputs as a function of the ego's speed."""

    name: str = ""

    @abstractmethod
    def inputs(self, v: FloatArray, settings: RiskSettings) -> tuple[FloatArray, FloatArray]:
        """Inputs when started at speed ``v``.

        Parameters
        ----------
        v : ndarray of shape (n,)
            Ego speed in m/s at the reaction steps (>= 0).
        settings : RiskSettings
            Holds the ego's capabilities.

        Returns
        -------
        a, omega : ndarray of shape (n,)
            Acceleration (m/s²) and turn rate (rad/s).
        """

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class Steer(Manoeuvre):
    """Full steering to one side at constant speed (``direction`` +1 = left, -1 = right)."""

    def __init__(self, direction: int) -> None:
        if direction not in (1, -1):
            raise RiskcoreError("Steer: direction must be +1 (left) or -1 (right)")
        self.direction = direction
        self.name = "steer_left" if direction == 1 else "steer_right"

    def inputs(self, v: FloatArray, settings: RiskSettings) -> tuple[FloatArray, FloatArray]:
        v = np.asarray(v, dtype=np.float64)
        lat, radius = settings.lat_accel_max, settings.min_turn_radius
        # min(lat / v, v / radius) without dividing by a tiny v: lat / v is the smaller one
        # exactly when v² >= lat · radius.
        fast = v * v >= lat * radius
        omega = np.where(fast, lat / np.where(fast, v, 1.0), v / radius)
        return np.zeros_like(v), self.direction * omega


class Brake(Manoeuvre):
    """Full braking straight ahead until standstill."""

    name = "brake"

    def inputs(self, v: FloatArray, settings: RiskSettings) -> tuple[FloatArray, FloatArray]:
        v = np.asarray(v, dtype=np.float64)
        return np.full_like(v, -settings.brake_max), np.zeros_like(v)


class Accelerate(Manoeuvre):
    """Full acceleration straight ahead."""

    name = "accelerate"

    def inputs(self, v: FloatArray, settings: RiskSettings) -> tuple[FloatArray, FloatArray]:
        v = np.asarray(v, dtype=np.float64)
        return np.full_like(v, settings.accel_max), np.zeros_like(v)


#: The four evasions of the paper, in mask-bit order.
MANOEUVRES: tuple[Manoeuvre, ...] = (Steer(1), Steer(-1), Brake(), Accelerate())


def evasion_names(mask: int, manoeuvres: tuple[Manoeuvre, ...] = MANOEUVRES
                  ) -> tuple[str, ...]:
    """Names of the manoeuvres whose bits are set in ``mask``."""
    return tuple(m.name for k, m in enumerate(manoeuvres) if int(mask) >> k & 1)


def evasion_label(mask: int, collides: bool,
                  manoeuvres: tuple[Manoeuvre, ...] = MANOEUVRES) -> str | None:
    """Text form of one trajectory's evasion, as in the JSON output.

    ``None`` when the trajectory does not collide; ``"none"`` when the collision cannot be
    avoided (TTR = 0); otherwise the names joined by ``"+"``, e.g. ``"steer_right+brake"``.
    """
    if not collides:
        return None
    names = evasion_names(mask, manoeuvres)
    return "+".join(names) if names else "none"
