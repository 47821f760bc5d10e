"""The region: which cut-ins a sample set lives in, and the quantities it is written in.

- :mod:`~sampler.region.constraints` — :class:`Constraint`, :func:`parse_constraint`,
  :class:`Region`, :func:`derive` and the quantity names;
- :mod:`~sampler.region.kinematics` — the cut-in's crossing kinematics, vectorised;
- :mod:`~sampler.region.criticality` — the criticality record's quantities straight from
  parameter vectors (riskcore's kernels, no scenario built);
- :mod:`~sampler.region.btn_bound` — an upper bound of ``btn`` from the kinematics alone.
"""

from sampler.region.btn_bound import a_req_bound, btn_bound
from sampler.region.constraints import (
    DERIVED,
    OPERATORS,
    PHYSICAL_BOUNDS,
    QUANTITY_NAMES,
    Constraint,
    Region,
    constraint_grammar,
    constraint_pattern,
    derive,
    implied_bounds,
    parse_constraint,
)
from sampler.region.criticality import CRITICALITY_QUANTITIES, criticality_quantities
from sampler.region.kinematics import CrossingKinematics, crossing_kinematics, plateau_speeds

__all__ = [
    "CRITICALITY_QUANTITIES",
    "DERIVED",
    "OPERATORS",
    "PHYSICAL_BOUNDS",
    "QUANTITY_NAMES",
    "Constraint",
    "CrossingKinematics",
    "Region",
    "a_req_bound",
    "btn_bound",
    "constraint_grammar",
    "constraint_pattern",
    "criticality_quantities",
    "crossing_kinematics",
    "derive",
    "implied_bounds",
    "parse_constraint",
    "plateau_speeds",
]
