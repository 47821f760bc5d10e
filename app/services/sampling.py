"""Sampling and scoring: cut-ins in a region drawn from a model, built and scored.

- ``sample_scenarios`` is ``POST /scenarios``: check the request against the service's
  limits, draw the vectors (``domain.sample``), score them on the service's executor while
  this thread adds the model interval and the rates, and return both.
- ``score_later`` starts the scoring of drawn vectors on a ``ChunkExecutor``, split in one
  part per worker slot; ``score_on_pool`` does it on a process pool of the caller's size
  (``scengen sample --workers``) with a per-scenario progress callback.
- ``reference_draws`` is a model's unconstrained reference (draws inside the physical
  bounds only), shared by the dashboard's views and the model comparison.
- ``split_constraints`` reads a region typed as one string (``"ttc<3; btn>0.7"``).
"""

from __future__ import annotations

import itertools
import multiprocessing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import pandas as pd

from app import domain
from app.context import ServiceContext
from app.errors import InvalidInput
from app.jobs.executors import ChunkExecutor
from app.jobs.lifeline import lifeline_pool
from app.limits import check_constraints
from sampler import CutInGMM
from sampler.methods import ProgressFn
from sampler.scenario import ScenarioRecord, score_part, score_samples

__all__ = ["MODEL_DRAWS", "POOL_MIN_N", "REFERENCE_SEED", "ScoredSample", "reference_draws",
           "sample_local", "sample_scenarios", "score_later", "score_on_pool",
           "split_constraints"]

#: below this many vectors the request scores them itself (a pool round trip costs more)
POOL_MIN_N = 8
#: model draws behind a model's unconstrained reference
MODEL_DRAWS = 5000
#: the model's unconstrained reference draws come from this seed (documented)
REFERENCE_SEED = 0
#: a command-line process is single-threaded: fork starts workers at once (spawn re-imports)
_POOL = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"


@dataclass(frozen=True)
class ScoredSample:
    """Vectors drawn in a region and their records (``POST /scenarios``)."""

    model_id: str
    drawn: domain.SampleResult
    records: list[ScenarioRecord]


def split_constraints(text: str) -> list[str]:
    """Constraints typed as one string: ``"ttc<3; v_ego>=20"`` (``;``, ``,`` or ``&``
    separate them; blanks are dropped)."""
    parts = [p.strip() for p in text.replace("&", ";").replace(",", ";").split(";")]
    return [p for p in parts if p]


def score_later(executor: ChunkExecutor, drawn: domain.SampleResult, *, seed: int,
                score: bool, include_scenario: bool,
                wagner_scan: bool = False) -> Callable[[], list[ScenarioRecord]]:
    """Start scoring the drawn vectors (``score_vector`` each) on ``executor``, split in
    one part per worker slot; the returned function waits for the records. A few
    vectors, or nothing to score, are done in this process when the function is called."""
    kwargs = {"lane_width": drawn.lane_width, "seed": seed, "score": score,
              "include_scenario": include_scenario, "wagner_scan": wagner_scan}
    table, weights = drawn.params, [float(w) for w in drawn.weights]
    # each vector's data support (sampler.model.support), copied to its record
    sset = drawn.sample_set
    support: list[dict[str, Any] | None] | None = (
        None if sset is None or sset.support is None else list(sset.support))
    n = len(table)
    if not score or n < POOL_MIN_N:
        return lambda: score_part(table, 0, weights, kwargs, support)
    parts = min(n, 4)
    starts = [n * k // parts for k in range(parts + 1)]
    pairs = list(itertools.pairwise(starts))
    results = executor.map_later(
        score_part, [table.iloc[a:b].reset_index(drop=True) for a, b in pairs],
        starts[:-1], [weights[a:b] for a, b in pairs], [kwargs] * parts,
        [None if support is None else support[a:b] for a, b in pairs])
    return lambda: [record for part in results() for record in part]


def sample_scenarios(ctx: ServiceContext, *, model: str | None, constraints: Sequence[str],
                     n: int, seed: int, method: str = "auto", score: bool = True,
                     include_scenario: bool = False, wagner_scan: bool = False) -> ScoredSample:
    """``n`` cut-ins of the model in the region, built and (with ``score``) scored, with
    P(A), its model interval and the rates; ``n`` at most the synchronous limit."""
    limit = ctx.settings.sync_n_limit
    if n > limit:
        raise InvalidInput(f"n = {n} is over the synchronous limit of {limit}; use "
                           "POST /catalogues for larger sets", field="body.n")
    model_id = ctx.resolve_model_id(model)
    fitted = ctx.model(model_id, field="body.model")
    check_constraints(list(constraints), ctx.settings)
    parsed = domain.parse_constraints(constraints)
    drawn = domain.sample(fitted, parsed, n, seed, method=method, report=False)
    later = score_later(ctx.executor, drawn, seed=seed, score=score,
                        include_scenario=include_scenario,
                        wagner_scan=wagner_scan)  # the workers score while ...
    domain.add_region_report(fitted, drawn)  # ... this thread adds the model interval, rates
    return ScoredSample(model_id=model_id, drawn=drawn, records=later())


def sample_local(model: CutInGMM, constraints: Sequence[str], n: int, seed: int | None, *,
                 method: str = "auto", lane_width: float | None = None,
                 use_envelope: bool = True,
                 progress: ProgressFn | None = None) -> domain.SampleResult:
    """``scengen sample``'s draw: ``n`` vectors of ``model`` in the region (no limits but
    the sampler's); ``progress`` hears the sampler's stages. The model interval and rates
    are left to the caller (``sampler.rates.region_report``); the records to
    ``score_on_pool``."""
    parsed = domain.parse_constraints(constraints, field="constraints")
    return domain.sample(model, parsed, n, seed, method, report=False, lane_width=lane_width,
                         use_envelope=use_envelope, progress=progress)


def score_on_pool(drawn: domain.SampleResult, *, workers: int, score: bool,
                  include_scenarios: bool, wagner_scan: bool = False,
                  progress: Callable[[int, int], None] | None = None) -> list[ScenarioRecord]:
    """Build and score the drawn vectors on a pool of ``workers`` processes that die with
    this one (``scengen sample``); records in sample order."""
    if drawn.sample_set is None:
        raise ValueError("score_on_pool: the draw has no sample set")
    with lifeline_pool(workers, _POOL) as pool:
        return score_samples(drawn.sample_set, executor=pool, score=score,
                             include_scenarios=include_scenarios, wagner_scan=wagner_scan,
                             progress=progress)


def reference_draws(ctx: ServiceContext, model_id: str, model: CutInGMM) -> pd.DataFrame:
    """The model's unconstrained reference: ``MODEL_DRAWS`` draws inside the physical
    bounds only (seed ``REFERENCE_SEED``), kept per model."""
    def compute() -> pd.DataFrame:
        drawn = domain.sample(model, [], MODEL_DRAWS, REFERENCE_SEED, method="rejection")
        return drawn.params

    frame: pd.DataFrame = ctx.cache("models.reference", 16).get(("reference", model_id),
                                                                compute)
    return frame
