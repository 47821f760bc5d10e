"""Run small linear algebra single-threaded.

The sampler's matrices are tiny (8 x 8); multi-threaded BLAS/OpenMP only adds
synchronisation, and on a loaded machine it is 10x slower (measured: scikit-learn's fit of
a 2-component mixture to 300 rows took 6 s instead of 0.6 s with 2 cores shared by other
jobs). ``single_threaded`` limits the native thread pools for the duration of a call.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

P = ParamSpec("P")
R = TypeVar("R")


def single_threaded(func: Callable[P, R]) -> Callable[P, R]:
    """Decorator: call ``func`` with BLAS and OpenMP limited to one thread."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1):
            return func(*args, **kwargs)

    return wrapper
