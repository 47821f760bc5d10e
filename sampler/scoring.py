"""Scoring glue: samples -> concrete scenarios -> riskcore scores, batched, optional pool.

``score_samples`` builds every sample's scenario (``sampler.builder.build_scenario``) and
scores it (default ``riskcore.evaluate_scenario``), in chunks of ``chunk_size`` samples.
With ``n_workers > 1`` the chunks run on a ``concurrent.futures.ProcessPoolExecutor``
(default start method ``spawn``: safe with numba, threaded BLAS and threaded servers, but a
calling script needs the ``if __name__ == "__main__":`` guard; ``mp_context="fork"`` starts
faster from a single-threaded command-line process); results come back in input order
whatever the number of workers, so the output is deterministic. Each chunk runs with BLAS
limited to one thread (one process per core is the parallelism).

A sample that cannot be built or scored does not stop the batch: its ``ScoredSample``
carries ``error`` (one line) and no risk.
"""

from __future__ import annotations

import functools
import multiprocessing
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import pandas as pd

from datasets.cutin_model import PARAM_NAMES
from riskcore.scenario import ConcreteScenario
from sampler._exceptions import SamplerError
from sampler._threads import single_threaded
from sampler.builder import build_scenario
from sampler.sampleset import SampleSet

__all__ = ["ScoredSample", "score_samples"]

Scorer = Callable[[ConcreteScenario], Any]


@dataclass(frozen=True)
class ScoredSample:
    """One sample's scenario and score.

    Attributes
    ----------
    index : int
        Position in the input.
    params : dict of str -> float
    scenario : ConcreteScenario or None
        None when building failed or ``keep_scenarios=False``.
    risk : object or None
        What the scorer returned (``riskcore.ScenarioRisk`` by default); None on error.
    error : str or None
    """

    index: int
    params: dict[str, float]
    scenario: ConcreteScenario | None
    risk: Any
    error: str | None = None

    def summary(self) -> dict[str, Any]:
        """The risk's ``summary()`` (riskcore) or ``{}``, plus ``error`` when set."""
        out: dict[str, Any] = {}
        if isinstance(self.risk, Mapping):
            out.update(self.risk)
        elif self.risk is not None and hasattr(self.risk, "summary"):
            out.update(self.risk.summary())
        if self.error is not None:
            out["error"] = self.error
        return out


def _default_scorer(scenario: ConcreteScenario, settings: Any = None,
                    surfaces: Any = None) -> Any:
    from riskcore import evaluate_scenario

    return evaluate_scenario(scenario, settings=settings, surfaces=surfaces)


@single_threaded
def _score_chunk(chunk: Sequence[tuple[int, dict[str, float]]], builder_kwargs: dict[str, Any],
                 scorer: Scorer, keep: bool, summary_only: bool = False) -> list[ScoredSample]:
    out = []
    for index, params in chunk:
        kw = dict(builder_kwargs)
        prov = dict(kw.pop("provenance", None) or {})
        prov["sample_index"] = index
        try:
            scen = build_scenario(params, provenance=prov, **kw)
        except ValueError as exc:
            out.append(ScoredSample(index, params, None, None, f"build: {exc}"))
            continue
        try:
            risk = scorer(scen)
        except ValueError as exc:
            out.append(ScoredSample(index, params, scen if keep else None, None,
                                    f"score: {exc}"))
            continue
        if summary_only and hasattr(risk, "summary"):
            risk = dict(risk.summary())
        out.append(ScoredSample(index, params, scen if keep else None, risk))
    return out


def _rows(samples: SampleSet | pd.DataFrame | Iterable[Mapping[str, float]]
          ) -> list[dict[str, float]]:
    if isinstance(samples, SampleSet):
        return [samples.params_dict(i) for i in range(len(samples))]
    if isinstance(samples, pd.DataFrame):
        missing = [k for k in PARAM_NAMES if k not in samples.columns]
        if missing:
            raise SamplerError(f"samples: missing column(s) {', '.join(missing)}")
        return [{k: float(row[k]) for k in PARAM_NAMES}
                for _, row in samples[list(PARAM_NAMES)].iterrows()]
    rows = []
    for i, r in enumerate(samples):
        if not isinstance(r, Mapping):
            raise SamplerError(f"samples[{i}]: expected a mapping of parameters")
        rows.append({str(k): float(v) for k, v in r.items()})
    return rows


def score_samples(
    samples: SampleSet | pd.DataFrame | Iterable[Mapping[str, float]],
    *,
    n_workers: int = 1,
    chunk_size: int = 20,
    builder_kwargs: Mapping[str, Any] | None = None,
    settings: Any = None,
    surfaces: Any = None,
    scorer: Scorer | None = None,
    keep_scenarios: bool = True,
    summary_only: bool = False,
    mp_context: str = "spawn",
    progress: Callable[[int, int], None] | None = None,
) -> list[ScoredSample]:
    """Build and score every sample; results in input order.

    Parameters
    ----------
    samples : SampleSet, DataFrame with ``PARAM_NAMES`` columns, or mappings
        A SampleSet passes its seed and lane width to the builder.
    n_workers : int
        1 runs in this process; more use a process pool of that size.
    chunk_size : int
        Samples per task.
    builder_kwargs : mapping, optional
        Passed to ``build_scenario`` (``dt``, ``duration``, ``lead_in``, ...).
    settings, surfaces : optional
        riskcore ``RiskSettings`` and ``InputSurfaces`` for the default scorer.
    scorer : callable(ConcreteScenario) -> object, optional
        Replaces riskcore (it must be picklable, i.e. a module-level function, for a pool).
    keep_scenarios : bool
        Keep each ConcreteScenario in the result (memory: ~20 kB each).
    summary_only : bool
        Keep only the risk's ``summary()`` dict instead of the full ``ScenarioRisk``
        (~600 kB each when pickled back from a worker: with a pool, this is most of the
        cost).
    mp_context : {"spawn", "forkserver", "fork"}
        Start method of the pool. ``spawn`` (default) is safe anywhere, including inside a
        threaded server, but each worker re-imports the packages (seconds); ``fork`` starts
        at once and suits a single-threaded command-line process on POSIX.
    progress : callable(done, total), optional

    Returns
    -------
    list of ScoredSample, one per sample, in input order.
    """
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise SamplerError(f"n_workers: expected an integer >= 1, got {n_workers!r}")
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise SamplerError(f"chunk_size: expected an integer >= 1, got {chunk_size!r}")
    if mp_context not in multiprocessing.get_all_start_methods():
        raise SamplerError(f"mp_context: {mp_context!r} is not available here; valid: "
                           f"{', '.join(multiprocessing.get_all_start_methods())}")
    rows = _rows(samples)
    kw: dict[str, Any] = dict(builder_kwargs or {})
    if isinstance(samples, SampleSet):
        kw.setdefault("lane_width", samples.region.lane_width)
        kw.setdefault("seed", samples.seed)
    fn: Scorer = scorer or functools.partial(_default_scorer, settings=settings,
                                             surfaces=surfaces)
    chunks = [list(enumerate(rows))[i:i + chunk_size] for i in range(0, len(rows), chunk_size)]
    total = len(rows)
    out: list[ScoredSample] = []
    if n_workers == 1 or len(chunks) <= 1:
        for chunk in chunks:
            out.extend(_score_chunk(chunk, kw, fn, keep_scenarios, summary_only))
            if progress is not None:
                progress(len(out), total)
        return out
    ctx = multiprocessing.get_context(mp_context)
    with ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx) as pool:
        n_c = len(chunks)
        for result in pool.map(_score_chunk, chunks, [kw] * n_c, [fn] * n_c,
                               [keep_scenarios] * n_c, [summary_only] * n_c):
            out.extend(result)
            if progress is not None:
                progress(len(out), total)
    return out
