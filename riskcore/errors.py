"""The exceptions of riskcore, drawn once here.

::

    ValueError
     └── RiskcoreError            any bad input to riskcore; the message names the field
          ├── ScenarioError       a malformed concrete scenario (riskcore.scenario)
          ├── SettingsError       a RiskSettings field out of range
          ├── SurfaceError        a malformed input-surfaces file or object
          └── SceneError          a malformed scene (ego future, object state)

They subclass ``ValueError`` so callers (the CLI, the API) can treat every one of them as
a user error: one line, no traceback.
"""

from __future__ import annotations

from typing import Any

__all__ = ["RiskcoreError", "SceneError", "SettingsError", "SurfaceError"]


class RiskcoreError(ValueError):
    """Base class: bad input to riskcore. The message names the field and the problem;
    ``field`` holds the field's dotted path (e.g. ``"ego.v[3]"``) when one field is to
    blame, else None; ``problem`` a short phrase (``"not finite"``, ``"out of range"``) and
    ``value`` the offending value, when the raiser gives them."""

    def __init__(self, message: str, *, field: str | None = None, problem: str | None = None,
                 value: Any = None) -> None:
        super().__init__(message)
        self.field = field
        self.problem = problem
        self.value = value


class SettingsError(RiskcoreError):
    """A :class:`~riskcore.settings.RiskSettings` field is out of range."""


class SurfaceError(RiskcoreError):
    """An input-surfaces file or mapping is malformed."""


class SceneError(RiskcoreError):
    """A scene (the ego's future, an object's state) is malformed."""
