"""sampler: GMM scenario model, constraints, constrained sampling, scenario builder.

Public surface (docs/sampler.md)::

    CutInGMM                                   the scenario model (fit, log_density, JSON)
    Constraint, parse_constraint, Region       constraints as data
    sample, estimate_p_region -> SampleSet     constrained sampling with P(A)
    RejectionSampler, MCMCSampler, AutoSampler the sampler strategies
    SAMPLER_NAMES                              the samplers' names (``sample(method=...)``)
    PRegion, PRegionEstimator                  P(A) with its interval
    build_scenario                             parameter vector -> ConcreteScenario
    score_vector, ScenarioRecord               one vector -> scenario -> scored record
    score_samples                              many vectors -> records (optional pool)
"""

from sampler.errors import (
    BuilderError,
    ConstraintError,
    EmptyRegionError,
    LevelsNotConvergedError,
    ModelError,
    NotFittedError,
    SamplerError,
)
from sampler.methods.probability import PRegion, PRegionEstimator
from sampler.methods.samplers import (
    SAMPLER_NAMES,
    AutoSampler,
    MCMCSampler,
    RejectionSampler,
    Sampler,
)
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import (
    DERIVED,
    PHYSICAL_BOUNDS,
    QUANTITY_NAMES,
    Constraint,
    Region,
    derive,
    parse_constraint,
)
from sampler.sampling import SampleSet, estimate_p_region, sample
from sampler.scenario.builder import build_scenario
from sampler.scenario.record import ScenarioRecord, score_vector
from sampler.scenario.scoring import score_samples

__all__ = [
    "DERIVED",
    "PHYSICAL_BOUNDS",
    "QUANTITY_NAMES",
    "SAMPLER_NAMES",
    "AutoSampler",
    "BuilderError",
    "Constraint",
    "ConstraintError",
    "CutInGMM",
    "EmptyRegionError",
    "LevelsNotConvergedError",
    "MCMCSampler",
    "ModelError",
    "NotFittedError",
    "PRegion",
    "PRegionEstimator",
    "Region",
    "RejectionSampler",
    "SampleSet",
    "Sampler",
    "SamplerError",
    "ScenarioRecord",
    "build_scenario",
    "derive",
    "estimate_p_region",
    "parse_constraint",
    "sample",
    "score_samples",
    "score_vector",
]
