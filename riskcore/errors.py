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

__all__ = ["RiskcoreError", "SceneError", "SettingsError", "SurfaceError"]


class RiskcoreError(ValueError):
    """Base class: bad input to riskcore. The message names the field and the problem."""


class SettingsError(RiskcoreError):
    """A :class:`~riskcore.settings.RiskSettings` field is out of range."""


class SurfaceError(RiskcoreError):
    """An input-surfaces file or mapping is malformed."""


class SceneError(RiskcoreError):
    """A scene (the ego's future, an object's state) is malformed."""
