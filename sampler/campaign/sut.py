"""A runner that drives a system under test: the batches of cut-ins
(``sampler.scenario.buildable_batches``, the builder's tracks, each run on its own grid
so that its outcome is a function of its own vector, seed and settings) through
riskcore's closed-loop simulator (``riskcore.sut.simulate``), and the same runs with UN
R157's careful driver (``r157_cc``) for ``vs_careful``.

A vector the builder refuses (no crossing at this lane width, a non-positive ego speed,
a reversing cutter) is not a cut-in: it is not simulated and counts as no collision
(``buildable`` False). The campaign's region already keeps such vectors out by its
physical bounds; the two tests differ only at the edges (the region's crossing
kinematics integrate on a coarser grid).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riskcore.sut import (
    RUN_FIELDS,
    RunBatch,
    SimSettings,
    SystemUnderTest,
    compare_careful,
    make_sut,
    simulate,
)
from sampler.scenario.batch import buildable_batches
from sampler.scenario.builder import DEFAULT_VEHICLE_SIZE

__all__ = ["SutRuns", "sut_runner"]

FloatArray = NDArray[np.float64]


@dataclass
class SutRuns:
    """The runs of a SUT: every field of ``riskcore.sut.RunBatch`` as (n,) arrays (rows
    not buildable: no collision, NaN margins), plus ``buildable``, ``careful_collided``,
    ``careful_impact_speed`` and ``vs_careful`` (``worse``/``same``/``better``; "" without
    the careful run)."""

    arrays: dict[str, NDArray[Any]]

    def __getattr__(self, name: str) -> Any:
        try:
            return self.__dict__["arrays"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __len__(self) -> int:
        return int(self.arrays["collided"].shape[0])

    def __reduce__(self) -> tuple[Any, ...]:  # picklable for process pools
        return (SutRuns, (self.arrays,))


def _full(parts: list[tuple[NDArray[np.intp], RunBatch]], n: int) -> dict[str, NDArray[Any]]:
    """Every field as an (n,) array: the runs of each part at its rows, the rest not
    buildable."""
    out: dict[str, NDArray[Any]] = {}
    for name, spec in RUN_FIELDS.items():
        srcs = [(rows, np.asarray(getattr(runs, name))) for rows, runs in parts]
        if spec.kind == "bool":
            arr: NDArray[Any] = np.zeros(n, dtype=bool)
        elif spec.kind == "str":
            width = max([16] + [src.dtype.itemsize // 4 for _, src in srcs
                                if src.dtype.kind == "U"])
            arr = np.full(n, "not_buildable", dtype=f"<U{width}")
        else:
            arr = np.full(n, 0.0 if name == "impact_speed" else np.nan)
        for rows, src in srcs:
            arr[rows] = src
        out[name] = arr
    return out


@dataclass(frozen=True)
class SutRunner:
    """``runner(params, seeds)``: see :func:`sut_runner`."""

    factory: Callable[[], SystemUnderTest] = field(repr=False)
    settings: SimSettings | None
    careful: bool
    name: str
    lane_width: float | None
    vehicle_size: tuple[float, float] = DEFAULT_VEHICLE_SIZE
    risk: bool = False  # Wagner's r_dep / r_ind of the SUT's own drive (riskcore.sut)

    def _sut(self) -> SystemUnderTest:
        return self.factory()

    def __call__(self, params: FloatArray, seeds: NDArray[np.uint64]) -> SutRuns:
        x = np.asarray(params, dtype=np.float64)
        n = x.shape[0]
        length, width = self.vehicle_size
        lane = 3.75 if self.lane_width is None else self.lane_width
        # the tracks once, each row on its own grid (its outcome depends on it alone),
        # rows with the same grid in one batch
        _status, groups = buildable_batches(x, lane_width=lane, ego_length=length,
                                            ego_width=width, cutter_length=length,
                                            cutter_width=width)
        ok = np.zeros(n, dtype=bool)
        seeds = np.asarray(seeds, dtype=np.uint64)
        parts: list[tuple[NDArray[np.intp], RunBatch]] = []
        careful: list[tuple[NDArray[np.intp], RunBatch]] = []
        for rows, batch in groups:
            ok[rows] = True
            parts.append((rows, simulate(self._sut(), batch, seeds=seeds[rows],
                                         settings=self.settings, risk=self.risk)))
            if self.careful:
                careful.append((rows, simulate(make_sut("r157_cc"), batch,
                                               seeds=seeds[rows], settings=self.settings)))
        if parts:
            arrays = _full(parts, n)
            vs = np.full(n, "", dtype="<U6")
            if self.careful:
                arrays["careful_collided"] = np.zeros(n, dtype=bool)
                arrays["careful_impact_speed"] = np.zeros(n)
                for (rows, runs), (_, ref) in zip(parts, careful, strict=True):
                    arrays["careful_collided"][rows] = ref.collided
                    arrays["careful_impact_speed"][rows] = ref.impact_speed
                    vs[rows] = compare_careful(runs, ref)
            arrays["vs_careful"] = vs
        else:
            arrays = {"collided": np.zeros(n, dtype=bool), "impact_speed": np.zeros(n),
                      "vs_careful": np.full(n, "", dtype="<U6")}
        arrays["buildable"] = ok
        return SutRuns(arrays)


class _Fixed:
    """A factory that hands out one SUT object (not for parallel executors)."""

    def __init__(self, sut: SystemUnderTest) -> None:
        self.sut = sut

    def __call__(self) -> SystemUnderTest:
        return self.sut


def sut_runner(sut: SystemUnderTest | Callable[[], SystemUnderTest], *,
               settings: SimSettings | None = None, careful: bool = True,
               lane_width: float | None = None, name: str | None = None,
               vehicle_size: tuple[float, float] = DEFAULT_VEHICLE_SIZE,
               risk: bool = False) -> SutRunner:
    """A campaign runner driving ``sut`` (a SUT object, or a zero-argument factory that
    makes a fresh one per call: use a picklable factory with a process pool, and never
    share one SUT object between threads).

    ``careful``: also drive the same runs with ``r157_cc`` (UN R157's careful driver,
    JRC-FSM rule) for ``vs_careful`` (doubles the simulation cost). ``lane_width`` (m):
    None takes the campaign's (``evaluate`` sets its region's, the model's
    ``lane_width_``; 3.75 m when called directly). ``risk``: also compute Wagner's r_dep
    and r_ind of the SUT's own drive (``r_dep_peak``, ``r_ind_peak``, ``r_dep_time_above``;
    ``riskcore.sut.simulate(risk=True)``: costly, NaN without it).
    """
    if hasattr(sut, "act") and hasattr(sut, "reset"):
        factory: Callable[[], SystemUnderTest] = _Fixed(sut)  # type: ignore[arg-type]
        label = name or str(getattr(sut, "name", "sut"))
    else:
        factory = sut
        label = name or str(getattr(sut, "name", None) or getattr(sut, "__name__", "sut"))
    return SutRunner(factory=factory, settings=settings, careful=bool(careful), name=label,
                     lane_width=None if lane_width is None else float(lane_width),
                     vehicle_size=vehicle_size, risk=bool(risk))
