"""sampler: GMM scenario model, constraints, constrained sampling, scenario builder.

Public surface (see docs/sampler.md)::

    Constraint, parse_constraint, Region      constraints as data
    build_scenario                            parameter vector -> ConcreteScenario
"""

from sampler._exceptions import (
    BuilderError,
    ConstraintError,
    EmptyRegionError,
    ModelError,
    NotFittedError,
    SamplerError,
)
from sampler.builder import build_scenario
from sampler.constraints import (
    DERIVED,
    PHYSICAL_BOUNDS,
    QUANTITY_NAMES,
    Constraint,
    Region,
    derive,
    parse_constraint,
)

__all__ = [
    "DERIVED",
    "PHYSICAL_BOUNDS",
    "QUANTITY_NAMES",
    "BuilderError",
    "Constraint",
    "ConstraintError",
    "EmptyRegionError",
    "ModelError",
    "NotFittedError",
    "Region",
    "SamplerError",
    "build_scenario",
    "derive",
    "parse_constraint",
]
