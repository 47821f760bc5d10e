"""The exceptions of riskcore, drawn once here.

::

    ValueError
     └── FieldError               a bad value: field, problem, value (also sampler's base)
          └── RiskcoreError       any bad input to riskcore; the message names the field
               ├── ScenarioError  a malformed concrete scenario (riskcore.scenario)
               ├── SettingsError  a RiskSettings field out of range
               ├── SurfaceError   a malformed input-surfaces file or object
               └── SceneError     a malformed scene (ego future, object state)

They subclass ``ValueError`` so callers (the CLI, the API) can treat every one of them as
a user error: one line, no traceback.
"""

from __future__ import annotations

from typing import Any

__all__ = ["FieldError", "RiskcoreError", "SceneError", "SettingsError", "SurfaceError"]


class FieldError(ValueError):
    """A bad input value, with structured fields for callers that map the error (e.g. to
    an HTTP response) without reading the message: ``field`` the dotted path of the input
    to blame (e.g. ``"ego.v[3]"``, ``"constraints.0"``) or None; ``problem`` a short phrase
    (``"not finite"``, ``"out of range"``) or None; ``value`` the offending value or None.
    The base of riskcore's errors and of ``sampler.SamplerError``."""

    def __init__(self, message: str, *, field: str | None = None, problem: str | None = None,
                 value: Any = None) -> None:
        super().__init__(message)
        self.field = field
        self.problem = problem
        self.value = value


class RiskcoreError(FieldError):
    """Base class: bad input to riskcore. The message names the field and the problem;
    the structured fields are those of :class:`FieldError`."""


class SettingsError(RiskcoreError):
    """A :class:`~riskcore.settings.RiskSettings` field is out of range."""


class SurfaceError(RiskcoreError):
    """An input-surfaces file or mapping is malformed."""


class SceneError(RiskcoreError):
    """A scene (the ego's future, an object's state) is malformed."""
