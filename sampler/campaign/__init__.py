"""Campaigns: a system under test driven through importance-sampled cut-ins, and its
collision probability per cut-in and rate per hour with both intervals (docs/evaluation.md).

- :mod:`~sampler.campaign.runners` — the ``Runner`` protocol and stand-in runners with a
  known answer;
- :mod:`~sampler.campaign.sut` — ``sut_runner``: a system under test in riskcore's
  closed-loop simulator (and the careful driver beside it);
- :mod:`~sampler.campaign.proposal` — the defensive mixture the runs are drawn from;
- :mod:`~sampler.campaign.evaluate` — ``evaluate()``, its chunks and its figures;
- :mod:`~sampler.campaign.reliability` — when a summary is not to be trusted (its
  ``warnings``).
"""

from sampler.campaign.evaluate import (
    DEFAULT_RHW,
    DEFAULT_ROULETTE,
    MAX_ROULETTE,
    ROULETTE_FINAL_ALPHA,
    CampaignResult,
    ChunkResult,
    evaluate,
    next_ce_proposal,
)
from sampler.campaign.proposal import DEFAULT_ENVELOPES, Proposal, build_proposal
from sampler.campaign.reliability import MIN_COLLISIONS, MIN_ESS, interval_reasons, with_verdict
from sampler.campaign.reliability import warnings as summary_warnings
from sampler.campaign.runners import (
    Outcomes,
    Runner,
    StandInRuns,
    halfspace_probability,
    halfspace_runner,
    late_brake_runner,
    union_probability,
    union_runner,
)
from sampler.campaign.sut import SutRunner, SutRuns, sut_runner

__all__ = [
    "DEFAULT_ENVELOPES",
    "DEFAULT_RHW",
    "DEFAULT_ROULETTE",
    "MAX_ROULETTE",
    "MIN_COLLISIONS",
    "MIN_ESS",
    "ROULETTE_FINAL_ALPHA",
    "CampaignResult",
    "ChunkResult",
    "Outcomes",
    "Proposal",
    "Runner",
    "StandInRuns",
    "SutRunner",
    "SutRuns",
    "build_proposal",
    "evaluate",
    "halfspace_probability",
    "halfspace_runner",
    "interval_reasons",
    "late_brake_runner",
    "next_ce_proposal",
    "summary_warnings",
    "sut_runner",
    "union_probability",
    "union_runner",
    "with_verdict",
]
