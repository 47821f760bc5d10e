"""The system-under-test protocol: batched (:class:`SystemUnderTest`) and per run
(:class:`PerRunSUT`, wrapped by :func:`per_run`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from riskcore.sut.batch import Observation, Observations
from riskcore.sut.errors import SutError

__all__ = ["PerRunSUT", "SystemUnderTest", "per_run"]


@runtime_checkable
class SystemUnderTest(Protocol):
    """Something that drives the ego of N runs at once.

    ``reset(n, seeds)`` is called once before a simulation with the number of runs and one
    seed per run (uint64): a SUT with randomness draws it from these seeds only
    (``np.random.default_rng(seed)`` per run), so the same seeds give the same drive, bit
    for bit. ``act(obs)`` returns the ego's longitudinal acceleration command for every
    run, shape (N,), m/s² (the simulator clips it to its limits and applies it until the
    next call). Lateral control is not supported: the ego keeps its lane.

    Optional: after ``act`` a SUT may set ``command_onset`` (N,) to a time within the
    coming step (``obs.t <= onset < obs.t + obs.dt``) from which the new command applies
    (the previous one before; NaN: from the step's start). The reference drivers use it
    to brake at their exact, interpolated moment, as the criticality record does.
    """

    name: str

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None: ...

    def act(self, obs: Observations) -> NDArray[np.float64]: ...


@runtime_checkable
class PerRunSUT(Protocol):
    """A plain controller for one run: ``reset(seed)`` then ``act(obs) -> float`` m/s²."""

    def reset(self, seed: int) -> None: ...

    def act(self, obs: Observation) -> float: ...


class _PerRun:
    """:func:`per_run`'s adapter: one controller per run, asked in a Python loop."""

    def __init__(self, factory: Callable[[], PerRunSUT], name: str) -> None:
        self.name = name
        self._factory = factory
        self._runs: list[PerRunSUT] = []

    def reset(self, n: int, seeds: NDArray[np.uint64]) -> None:
        seeds = np.asarray(seeds, dtype=np.uint64)
        if seeds.shape != (n,):
            raise SutError(f"seeds: expected shape ({n},), got {seeds.shape}")
        self._runs = []
        for s in seeds:
            ctrl = self._factory()
            ctrl.reset(int(s))
            self._runs.append(ctrl)

    def act(self, obs: Observations) -> NDArray[np.float64]:
        out = np.empty(len(self._runs))
        for i, ctrl in enumerate(self._runs):
            out[i] = float(ctrl.act(obs.run(i)))
        return out


def per_run(factory: Callable[[], PerRunSUT], name: str) -> SystemUnderTest:
    """A batched SUT made of one ``factory()`` controller per run (each reset with its
    run's seed as a Python int). Slow (a Python call per run and step) but simple."""
    if not callable(factory):
        raise SutError("factory: expected a callable returning a per-run SUT")
    return _PerRun(factory, name)
