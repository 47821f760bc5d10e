"""Exceptions of the sampler package.

Hierarchy (every one is a ``ValueError``, so the CLI reports it as one line, exit 2)::

    SamplerError
    ├── ConstraintError      a constraint or region is malformed (unknown name, operator)
    ├── ModelError           fitting, loading or using the GMM failed (bad table, bad JSON)
    │   └── NotFittedError   a method needs a fitted model
    ├── BuilderError         a parameter vector cannot become a concrete scenario
    ├── EmptyRegionError     the region has (practically) no probability mass
    └── LevelsNotConvergedError  subset levels met the region but could not converge on it
"""

from __future__ import annotations

from typing import Any

from riskcore import FieldError

__all__ = [
    "BuilderError",
    "ConstraintError",
    "EmptyRegionError",
    "LevelsNotConvergedError",
    "ModelError",
    "NotFittedError",
    "SamplerError",
]


class SamplerError(FieldError):
    """Base class of every error raised by ``sampler``; structured fields ``field``,
    ``problem``, ``value`` as in ``riskcore.errors.FieldError`` (e.g. ``"constraints.0"``,
    ``"unknown quantity"``, ``"foo"``)."""


class ConstraintError(SamplerError):
    """A constraint or a region is malformed. The message lists the valid choices;
    ``constraint`` holds the constraint's text when one constraint is to blame."""

    def __init__(self, message: str, *, constraint: str | None = None, **fields: Any) -> None:
        super().__init__(message, **fields)
        self.constraint = constraint


class ModelError(SamplerError):
    """Fitting, loading or evaluating the scenario model failed. The message names the field."""


class NotFittedError(ModelError):
    """The model must be fitted (or loaded) first."""


class BuilderError(SamplerError):
    """A parameter vector cannot be turned into a concrete scenario."""


class EmptyRegionError(SamplerError):
    """The region has no (or too little) probability mass to sample within the draw budget.

    Attributes
    ----------
    n_draws : int
        Model draws spent looking for the region.
    n_hits : int
        Draws that fell inside the region.
    p_upper : float
        One-sided 95 % upper bound of the region's mass found by the search.
    stalled : float or None
        Subset simulation only: the threshold its levels repeated when they stalled (the
        chains did not move, so ``p_upper`` is not a reliable bound), else None.
    """

    def __init__(self, message: str, *, n_draws: int = 0, n_hits: int = 0,
                 p_upper: float = float("nan"), stalled: float | None = None) -> None:
        super().__init__(message, field="constraints", problem="empty region")
        self.n_draws = n_draws
        self.n_hits = n_hits
        self.p_upper = p_upper
        self.stalled = stalled


class LevelsNotConvergedError(SamplerError):
    """Subset simulation evaluated rows inside the region, but its levels did not converge
    on it (their Markov chains barely move: a thin region). Unlike ``EmptyRegionError``
    this bounds nothing: the region may hold much mass.

    Attributes
    ----------
    n_draws : int
        Limit-state evaluations spent.
    n_hits : int
        Evaluated rows inside the region.
    """

    def __init__(self, message: str, *, n_draws: int = 0, n_hits: int = 0) -> None:
        super().__init__(message, field="constraints", problem="levels did not converge")
        self.n_draws = n_draws
        self.n_hits = n_hits
