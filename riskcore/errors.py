"""The one exception tree of scengen, drawn here at its root (riskcore is the floor every
package may import).

::

    ValueError
     └── FieldError                    the neutral base: a bad input, with field, problem, value
          ├── RiskcoreError             bad input to riskcore; the message names the field
          │    ├── ScenarioError        a malformed concrete scenario (riskcore.scenario)
          │    ├── CriticalityError     a scenario the criticality record cannot rate
          │    ├── SettingsError        a RiskSettings field out of range
          │    ├── SurfaceError         a malformed input-surfaces file or object
          │    └── SceneError           a malformed scene (ego future, object state)
          ├── DatasetError              datasets: FormatError, ExtractionError, CutInParamError
          ├── SamplerError              sampler: ConstraintError, ModelError (NotFittedError),
          │                             BuilderError, EmptyRegionError, LevelsNotConvergedError
          └── ExportError               app.exports: a catalogue that cannot be written so

The app's own errors (``app.errors.ServiceError``: NotFound, InvalidInput, Conflict, ...)
carry an HTTP status and sit beside this tree, not in it.

A ``FieldError`` is the user's fault: the service answers it with a 4xx naming ``field`` and
the CLI with one line and exit code 2. Any other exception -- a ``ValueError`` raised inside
numpy, scipy or scikit-learn included -- is our bug: the service answers 500 and logs the
trace, the CLI prints one line that says so (exit code 70) and the trace with
``SCENGEN_DEBUG=1``. So code that checks a user's input raises a ``FieldError`` subclass,
never a bare ``ValueError``.
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
