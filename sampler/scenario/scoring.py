"""Score many samples: :func:`sampler.scenario.record.score_vector` over a table, in parts.

``score_samples`` turns every sample into a :class:`~sampler.scenario.record.ScenarioRecord`
(build the scenario, score it with riskcore), in parts of ``chunk_size`` samples. sampler
starts no processes: given an ``executor`` (any ``concurrent.futures.Executor``; the app's
pools are in :mod:`app.jobs`, whose workers die with their parent) the parts run on it;
results come back in input order whatever the executor, so the output is deterministic.
Each part runs with BLAS limited to one thread (one process per core is the parallelism).

A sample that cannot be built or scored does not stop the batch: its record carries
``error`` (one line) and no scores (the policy of ``score_vector``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Executor
from typing import Any, Protocol, TypeGuard, cast, runtime_checkable

import pandas as pd

from datasets import PARAM_NAMES
from riskcore import InputSurfaces, RiskSettings
from sampler._threads import single_threaded
from sampler.errors import SamplerError
from sampler.scenario.record import ScenarioRecord, score_rows

__all__ = ["score_part", "score_samples"]


@runtime_checkable
class _Samples(Protocol):
    """What a :class:`sampler.SampleSet` gives the scoring (its table, seed, lane width and
    exposure weights); a protocol, so this module does not import the sampling layer."""

    @property
    def params(self) -> pd.DataFrame: ...
    @property
    def seed(self) -> int: ...
    @property
    def lane_width(self) -> float: ...
    @property
    def exposure_weights(self) -> Any: ...


def _provenance(index: int) -> dict[str, Any]:
    return {"sample_index": index}


@single_threaded
def score_part(table: pd.DataFrame, start: int, weights: list[float] | None,
               kwargs: dict[str, Any], support: list[dict[str, Any] | None] | None = None
               ) -> list[ScenarioRecord]:
    """Records of the rows of ``table`` with indices ``start, start + 1, ...`` (a pool
    task: module-level, picklable; the scenarios' provenance is their sample index);
    ``support``: each row's data support (``SampleSet.support``), copied to its record."""
    return [record for record, _ in score_rows(table, start=start, exposure_weights=weights,
                                                provenance=_provenance, support=support,
                                                **kwargs)]


def _is_sample_set(samples: object) -> TypeGuard[_Samples]:
    # a DataFrame answers attribute lookups with its columns: never take it for a set
    return not isinstance(samples, pd.DataFrame) and isinstance(samples, _Samples)


def _table(samples: _Samples | pd.DataFrame | Iterable[Mapping[str, float]]) -> pd.DataFrame:
    if _is_sample_set(samples):
        return samples.params
    if isinstance(samples, pd.DataFrame):
        missing = [k for k in PARAM_NAMES if k not in samples.columns]
        if missing:
            raise SamplerError(f"samples: missing column(s) {', '.join(missing)}")
        return samples
    rows = []
    for i, r in enumerate(cast(Iterable[Mapping[str, float]], samples)):
        if not isinstance(r, Mapping):
            raise SamplerError(f"samples[{i}]: expected a mapping of parameters")
        rows.append({str(k): float(v) for k, v in r.items()})
    table = pd.DataFrame(rows)
    missing = [k for k in PARAM_NAMES if k not in table.columns]
    if missing and rows:
        raise SamplerError(f"samples: missing parameter(s) {', '.join(missing)}")
    return table


def score_samples(
    samples: _Samples | pd.DataFrame | Iterable[Mapping[str, float]],
    *,
    executor: Executor | None = None,
    chunk_size: int = 20,
    builder_kwargs: Mapping[str, Any] | None = None,
    settings: RiskSettings | None = None,
    surfaces: InputSurfaces | None = None,
    score: bool = True,
    include_scenarios: bool = False,
    wagner_scan: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> list[ScenarioRecord]:
    """Build and score every sample; records in input order.

    Parameters
    ----------
    samples : SampleSet, DataFrame with ``PARAM_NAMES`` columns, or mappings
        A SampleSet passes its seed, lane width and exposure weights.
    executor : concurrent.futures.Executor, optional
        Runs the parts (``score_part`` is module-level and picklable); None: in this
        process, one part after the other.
    chunk_size : int
        Samples per part.
    builder_kwargs : mapping, optional
        Passed to ``build_scenario`` (``dt``, ``duration``, ``lead_in``, ...).
    settings, surfaces : optional
        riskcore ``RiskSettings`` and ``InputSurfaces``.
    score : bool
        False: only build (with ``include_scenarios``) or nothing; the records have no scores.
    include_scenarios : bool
        Put each scenario's JSON form in its record (~20 kB each).
    wagner_scan : bool
        Also ``alarm_time`` and ``risk_peak`` (``score_vector``; most of the cost).
    progress : callable(done, total), optional

    Returns
    -------
    list of ScenarioRecord, one per sample, in input order (``index`` = position).
    """
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise SamplerError(f"chunk_size: expected an integer >= 1, got {chunk_size!r}")
    table = _table(samples)
    kw: dict[str, Any] = {"builder_kwargs": dict(builder_kwargs or {}), "settings": settings,
                          "surfaces": surfaces, "score": score,
                          "include_scenario": include_scenarios,
                          "wagner_scan": wagner_scan}
    parts = _parts(samples, table, chunk_size, kw)
    total = len(table)
    out: list[ScenarioRecord] = []
    if executor is None or len(parts) <= 1:
        for part, start, w, sup in parts:
            out.extend(score_part(part, start, w, kw, sup))
            if progress is not None:
                progress(len(out), total)
        return out
    futures = [executor.submit(score_part, part, start, w, kw, sup)
               for part, start, w, sup in parts]
    for fut in futures:
        out.extend(fut.result())
        if progress is not None:
            progress(len(out), total)
    return out


_Part = tuple[pd.DataFrame, int, list[float] | None, list[dict[str, Any] | None] | None]


def _parts(samples: _Samples | pd.DataFrame | Iterable[Mapping[str, float]], table: pd.DataFrame,
           chunk_size: int, kw: dict[str, Any]) -> list[_Part]:
    """The table in parts of ``chunk_size`` rows: (rows, first index, exposure weights,
    support). A SampleSet also gives ``kw`` its lane width and seed."""
    weights: list[float] | None = None
    support: list[dict[str, Any] | None] | None = None
    if _is_sample_set(samples):
        kw["lane_width"] = samples.lane_width
        kw["seed"] = samples.seed
        weights = [float(w) for w in samples.exposure_weights]
        support = getattr(samples, "support", None)
    starts = list(range(0, len(table), chunk_size))
    return [(table.iloc[s:s + chunk_size].reset_index(drop=True), s,
             None if weights is None else weights[s:s + chunk_size],
             None if support is None else support[s:s + chunk_size]) for s in starts]
