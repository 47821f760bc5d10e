"""The service's use of the domain packages (datasets, sampler, riskcore), typed.

``app`` imports the domain packages directly; these modules hold what the service adds
around them (hashes and upload reading, model descriptions, sampling results as JSON,
scoring a posted scenario) and turn the domain's errors into ``InvalidInput`` naming the
request field:

- ``app.domain.data``      the embedded TNO table, uploaded files, content hashes
- ``app.domain.model``     load and describe the cut-in GMM; the dashboard's densities
- ``app.domain.sampling``  constraints, samples, P(A)
- ``app.domain.risk``      score a posted scenario; a scenario's risk profile on demand

One parameter vector becomes a scored record in ``sampler.scenario.record.score_vector`` (the
route, the catalogue chunk and the CLI call it directly).
"""

from app.domain.data import (
    DATASET_KINDS,
    dataset_from_files,
    embedded_parameter_table,
    embedded_source_hash,
    options_hash,
    table_hash,
)
from app.domain.model import (
    FittedModel,
    describe,
    describe_model,
    load_model,
    marginal_density,
    model_components,
    model_draws,
    model_features,
    model_lane_width,
)
from app.domain.risk import parse_scenario, risk_report, scenario_risk_series, score_posted
from app.domain.sampling import (
    SampleResult,
    add_region_report,
    estimate_region,
    parse_constraints,
    region_uncertainty,
    sample,
)
from datasets import PARAM_NAMES

__all__ = [
    "DATASET_KINDS",
    "PARAM_NAMES",
    "FittedModel",
    "SampleResult",
    "add_region_report",
    "dataset_from_files",
    "describe",
    "describe_model",
    "embedded_parameter_table",
    "embedded_source_hash",
    "estimate_region",
    "load_model",
    "marginal_density",
    "model_components",
    "model_draws",
    "model_features",
    "model_lane_width",
    "options_hash",
    "parse_constraints",
    "parse_scenario",
    "region_uncertainty",
    "risk_report",
    "sample",
    "scenario_risk_series",
    "score_posted",
    "table_hash",
]
