"""Score many samples: :func:`sampler.record.score_vector` over a table, batched, optional pool.

``score_samples`` turns every sample into a :class:`~sampler.record.ScenarioRecord` (build
the scenario, score it with riskcore), in chunks of ``chunk_size`` samples. With
``n_workers > 1`` the chunks run on a ``concurrent.futures.ProcessPoolExecutor`` (default
start method ``spawn``: safe with numba, threaded BLAS and threaded servers, but a calling
script needs the ``if __name__ == "__main__":`` guard; ``mp_context="fork"`` starts faster
from a single-threaded command-line process; the workers die with the calling process
however it ends, see :mod:`sampler.lifeline`); results come back in input order whatever
the number of workers, so the output is deterministic. Each chunk runs with BLAS limited
to one thread (one process per core is the parallelism).

A sample that cannot be built or scored does not stop the batch: its record carries
``error`` (one line) and no scores (the policy of ``score_vector``).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import pandas as pd

from datasets.cutin_model import PARAM_NAMES
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces
from sampler._exceptions import SamplerError
from sampler._threads import single_threaded
from sampler.lifeline import die_with_parent
from sampler.record import ScenarioRecord, score_rows
from sampler.sampleset import SampleSet

__all__ = ["score_part", "score_samples"]


def _provenance(index: int) -> dict[str, Any]:
    return {"sample_index": index}


@single_threaded
def score_part(table: pd.DataFrame, start: int, weights: list[float] | None,
               kwargs: dict[str, Any]) -> list[ScenarioRecord]:
    """Records of the rows of ``table`` with indices ``start, start + 1, ...`` (a pool
    task: module-level, picklable; the scenarios' provenance is their sample index)."""
    return [record for record, _ in score_rows(table, start=start, exposure_weights=weights,
                                                provenance=_provenance, **kwargs)]


def _table(samples: SampleSet | pd.DataFrame | Iterable[Mapping[str, float]]) -> pd.DataFrame:
    if isinstance(samples, SampleSet):
        return samples.params
    if isinstance(samples, pd.DataFrame):
        missing = [k for k in PARAM_NAMES if k not in samples.columns]
        if missing:
            raise SamplerError(f"samples: missing column(s) {', '.join(missing)}")
        return samples
    rows = []
    for i, r in enumerate(samples):
        if not isinstance(r, Mapping):
            raise SamplerError(f"samples[{i}]: expected a mapping of parameters")
        rows.append({str(k): float(v) for k, v in r.items()})
    table = pd.DataFrame(rows)
    missing = [k for k in PARAM_NAMES if k not in table.columns]
    if missing and rows:
        raise SamplerError(f"samples: missing parameter(s) {', '.join(missing)}")
    return table


def score_samples(
    samples: SampleSet | pd.DataFrame | Iterable[Mapping[str, float]],
    *,
    n_workers: int = 1,
    chunk_size: int = 20,
    builder_kwargs: Mapping[str, Any] | None = None,
    settings: RiskSettings | None = None,
    surfaces: InputSurfaces | None = None,
    score: bool = True,
    include_scenarios: bool = False,
    mp_context: str = "spawn",
    progress: Callable[[int, int], None] | None = None,
) -> list[ScenarioRecord]:
    """Build and score every sample; records in input order.

    Parameters
    ----------
    samples : SampleSet, DataFrame with ``PARAM_NAMES`` columns, or mappings
        A SampleSet passes its seed, lane width and exposure weights.
    n_workers : int
        1 runs in this process; more use a process pool of that size.
    chunk_size : int
        Samples per task.
    builder_kwargs : mapping, optional
        Passed to ``build_scenario`` (``dt``, ``duration``, ``lead_in``, ...).
    settings, surfaces : optional
        riskcore ``RiskSettings`` and ``InputSurfaces``.
    score : bool
        False: only build (with ``include_scenarios``) or nothing; the records have no scores.
    include_scenarios : bool
        Put each scenario's JSON form in its record (~20 kB each).
    mp_context : {"spawn", "forkserver", "fork"}
        Start method of the pool. ``spawn`` (default) is safe anywhere, including inside a
        threaded server, but each worker re-imports the packages (seconds); ``fork`` starts
        at once and suits a single-threaded command-line process on POSIX.
    progress : callable(done, total), optional

    Returns
    -------
    list of ScenarioRecord, one per sample, in input order (``index`` = position).
    """
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise SamplerError(f"n_workers: expected an integer >= 1, got {n_workers!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise SamplerError(f"chunk_size: expected an integer >= 1, got {chunk_size!r}")
    if mp_context not in multiprocessing.get_all_start_methods():
        raise SamplerError(f"mp_context: {mp_context!r} is not available here; valid: "
                           f"{', '.join(multiprocessing.get_all_start_methods())}")
    table = _table(samples)
    kw: dict[str, Any] = {"builder_kwargs": dict(builder_kwargs or {}), "settings": settings,
                          "surfaces": surfaces, "score": score,
                          "include_scenario": include_scenarios}
    weights: list[float] | None = None
    if isinstance(samples, SampleSet):
        kw["lane_width"] = samples.region.lane_width
        kw["seed"] = samples.seed
        weights = [float(w) for w in samples.exposure_weights]
    total = len(table)
    starts = list(range(0, total, chunk_size))
    parts = [(table.iloc[s:s + chunk_size].reset_index(drop=True), s,
              None if weights is None else weights[s:s + chunk_size]) for s in starts]
    out: list[ScenarioRecord] = []
    if n_workers == 1 or len(parts) <= 1:
        for part, start, w in parts:
            out.extend(score_part(part, start, w, kw))
            if progress is not None:
                progress(len(out), total)
        return out
    ctx = multiprocessing.get_context(mp_context)
    # the workers end with this process however it ends (SIGKILL included): lifeline
    with ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx,
                             initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
        futures = [pool.submit(score_part, part, start, w, kw) for part, start, w in parts]
        for fut in futures:
            out.extend(fut.result())
            if progress is not None:
                progress(len(out), total)
    return out
