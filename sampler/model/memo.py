"""Quantities of a fitted model that every request with it would estimate again: kept on the
model object.

``P(B)`` (the physical bounds' mass, 32,768 plain draws and the crossing kinematics of each)
and the bootstrap "model" interval of a region (importance sampling from the replicates'
average) depend on the model and the region only, not on the samples a request draws.
They are estimated once per model object from a generator with a fixed seed
(:data:`MODEL_SEED`) and reused: every request with the model sees the same figures, and a
request does not pay for them again (``POST /scenarios`` spent 0.16 s on P(B) and 0.7 s on
the model interval of ``ttc<3`` per call before).

The memo lives in the model's ``__dict__`` (not in its JSON); ``CutInGMM.fit`` and
``sampler.model.bootstrap.bootstrap_fit`` clear it. Entries are computed outside any lock: two
threads may compute the same entry at once and store equal values.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, TypeVar

__all__ = ["MODEL_SEED", "clear", "memoised"]

#: seed of the generator of every memoised model-level estimate
MODEL_SEED = 20_211_001

#: entries kept per model (oldest dropped first)
MAX_ENTRIES = 64

_ATTR = "_scengen_memo"

T = TypeVar("T")


def clear(model: Any) -> None:
    """Forget what was memoised for ``model`` (after it was refitted or got replicates)."""
    model.__dict__.pop(_ATTR, None)


def memoised(model: Any, key: Hashable, compute: Callable[[], T]) -> T:
    """``compute()`` once per ``(model, key)``; later calls return the stored value."""
    store: dict[Hashable, Any] = model.__dict__.setdefault(_ATTR, {})
    try:
        value: T = store[key]
        return value
    except KeyError:
        pass
    value = compute()
    if len(store) >= MAX_ENTRIES:
        store.pop(next(iter(store)), None)
    store[key] = value
    return value
