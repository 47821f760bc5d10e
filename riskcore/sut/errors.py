"""The error of :mod:`riskcore.sut`."""

from riskcore.errors import RiskcoreError

__all__ = ["SutError"]


class SutError(RiskcoreError):
    """A system under test, a batch or a simulation setting is invalid (the message says
    which field and why)."""
