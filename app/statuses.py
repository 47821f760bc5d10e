"""The status objects of the service's jobs: what ``app.services.catalogues.describe``
returns, ``GET /catalogues/{id}`` answers, the dashboard's view 3 shows and
``scengen catalogue status`` prints; what ``app.services.evaluations.describe`` returns and
``GET /evaluations/{id}`` answers.

The typed object is the HTTP response as it is (its floats, its field order). The CLI and
the dashboard print the status the way the store holds it (counts as whole numbers, P(A)'s
keys in their stored order): :func:`catalogue_status_plain` gives that form.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import ConfigDict, Field, with_config
from typing_extensions import TypedDict  # pydantic reads it on Python 3.11

from app.rates import RegionRates
from app.schemas import ApiModel, PRegion

__all__ = ["CatalogueStage", "CatalogueStatus", "ChunkProgress", "EvaluationStatus",
           "EvaluationSummary", "catalogue_status_plain"]


class ChunkProgress(ApiModel):
    total: int
    done: int


class CatalogueStage(ApiModel):
    name: str = Field(description="what the running job is doing: 'estimating P(A): <the "
                      "estimator's stage>', 'sampling and scoring', 'refining the model "
                      "interval …'")
    done: int | None = Field(default=None, description="the stage's count so far (draws, "
                             "hits, …; null when it has none)")
    total: int | None = Field(default=None, description="what ``done`` runs to (the "
                              "pilot's budget, which it may not use up)")


#: a scored column's distribution summary (``app.db.repository.value_statistics``):
#: count, count_inf, min, max, mean, p05 … p95 of its finite values
ColumnSummary = dict[str, float]


class CatalogueStatus(ApiModel):
    """A catalogue's status; ``summary`` has count (and count_inf), min, max, mean and the
    percentiles p05 … p95 of each scored column's finite values (computed in SQL);
    ``classes`` the number of scenarios of each criticality class."""

    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="strings")

    id: str
    status: str = Field(description="queued | running | done | failed | cancelled")
    model: str
    n: int
    seed: int
    constraints: list[str]
    sampler: str
    score: bool
    wagner_scan: bool = Field(default=False, description="whether the scores include "
                              "Wagner's scan (alarm_time, risk_peak, risks at the crossing)")
    chunk_size: int
    chunks: ChunkProgress
    scenarios_stored: int
    scenarios_done: int = Field(description="scenarios stored plus, while the job runs, "
                                "those its workers report computed in unfinished chunks")
    progress: float = Field(description="scenarios_done / n, 0 … 1 (moves per scenario)")
    stage: CatalogueStage | None = Field(default=None, description="while running: the "
                                         "current stage (null otherwise)")
    p_region: PRegion | None = Field(description="the catalogue's P(A) estimate; "
                                     "mc_ci and model_ci: its two intervals")
    rates: RegionRates | None = Field(default=None, description="cut-ins of the region per "
                                      "hour / per 10^6 km with both intervals (when the "
                                      "model has an exposure)")
    summary: dict[str, ColumnSummary]
    classes: dict[str, int] = Field(default_factory=dict, description="scenarios per "
                                    "criticality class (docs/criticality.md)")
    error: str | None
    created_at: str
    updated_at: str
    finished_at: str | None
    # last: it came after the declared fields when it was an undeclared extra
    support: dict[str, int] = Field(default_factory=dict, description="scenarios per "
                                    "data-support class: inside, near, extrapolated "
                                    "(docs/sampler.md)")


#: the summary's keys that count scenarios (whole numbers in the plain form)
_COUNTS = ("count", "count_inf")
#: the plain form's key order (``describe``'s before it was typed: support after classes)
_PLAIN_ORDER = tuple(name for name in CatalogueStatus.model_fields if name != "support")
_PLAIN_ORDER = (*_PLAIN_ORDER[:_PLAIN_ORDER.index("classes") + 1], "support",
                *_PLAIN_ORDER[_PLAIN_ORDER.index("classes") + 1:])


def _stored_p_region(p: PRegion) -> dict[str, Any]:
    """P(A) in the order ``app.domain.sampling.region_dict`` stores it: the sampler's
    fields, then ``ci``, then what the uncertainty report added."""
    out: dict[str, Any] = p.model_dump(mode="json", exclude_unset=True)
    if "ci" in out and "ci_low" in out:
        declared = [k for k in out if k in PRegion.model_fields and k != "ci"]
        extra = [k for k in out if k not in PRegion.model_fields]
        out = {**{k: out[k] for k in declared}, "ci": out["ci"], **{k: out[k] for k in extra}}
    return out


def catalogue_status_plain(status: CatalogueStatus) -> dict[str, Any]:
    """The status as plain JSON values in the store's form: the summary's counts as whole
    numbers, P(A)'s keys in their stored order, nothing a stored object did not have
    (``scengen catalogue status``, the dashboard's view 3)."""
    fields = status.model_dump(mode="json", exclude_unset=True, exclude={"p_region"})
    fields["summary"] = {col: {k: int(v) if k in _COUNTS else v for k, v in stats.items()}
                         for col, stats in fields["summary"].items()}
    fields["p_region"] = None if status.p_region is None else _stored_p_region(status.p_region)
    return {k: fields[k] for k in _PLAIN_ORDER if k in fields}


@with_config(ConfigDict(extra="allow"))
class EvaluationSummary(TypedDict):
    """A finished evaluation's summary (``CampaignResult.summary()``, docs/evaluation.md):
    the campaign's figures (``p_collision``, ``rate_per_hour``, ``runs``, ``collisions``,
    ``ess``, ``acceleration``, ...) and the verdict on them. A plain dict at run time.
    The verdict is recomputed from the stored figures when read
    (``sampler.campaign.reliability``), so evaluations stored before it have it too."""

    warnings: Annotated[list[str], Field(
        description="why the figures are not to be trusted, one plain-English sentence "
        "each (too few collisions, a small effective sample size, no collision at all, "
        "stopped at max_runs before the stop rule, a cross-entropy campaign without its "
        "final stage); empty when reliable")]
    reliable: Annotated[bool, Field(description="true when warnings is empty")]


class EvaluationStatus(ApiModel):
    """An evaluation's status; ``spec`` and ``summary`` in the service's JSON form
    (non-finite floats as strings: ``app.jsonconv.decode`` gives the numbers back)."""

    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="strings")

    id: str
    status: str = Field(description="queued | running | done | failed | cancelled")
    sut: str
    model: str
    seed: int
    constraints: list[str]
    spec: dict[str, Any]
    runs_planned: int = Field(description="n, or max_runs with the stop rule")
    runs_done: int = Field(description="draws stored so far (simulated or not)")
    progress: float = Field(description="runs_done / runs_planned (1 when done; the stop "
                            "rule usually ends a campaign before max_runs)")
    chunks_done: int
    collisions_so_far: int
    runs_simulated: int = Field(description="stored runs the SUT drove (draws inside the "
                                "region and the physical bounds)")
    summary: EvaluationSummary | None = Field(description="once done: p_collision and "
                                              "rate_per_hour (estimate, ci, model_ci), "
                                              "runs, collisions, ess, acceleration, ..., "
                                              "warnings and reliable (docs/evaluation.md)")
    error: str | None
    href_runs: str
    created_at: str
    updated_at: str
    finished_at: str | None
