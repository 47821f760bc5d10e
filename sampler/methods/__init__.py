"""The methods: drawing from the model restricted to a region, and P(A).

- :mod:`~sampler.methods.problem` — the sampling problem and the samplers' interface;
- :mod:`~sampler.methods.samplers` — the strategies (rejection, MCMC, subset, subset-is,
  auto) and the one list of their names, :data:`SAMPLERS`;
- :mod:`~sampler.methods.envelope` — half-space envelopes: exact draws of a superset;
- :mod:`~sampler.methods.mcmc` — emcee's ensemble sampler in z-space;
- :mod:`~sampler.methods.subset`, :mod:`~sampler.methods.rare`,
  :mod:`~sampler.methods.importance`, :mod:`~sampler.methods.strata` — rare regions
  (subset simulation, then importance sampling, optionally stratified);
- :mod:`~sampler.methods.probability` — P(A) with its interval.
"""

from sampler.methods.envelope import HalfSpace, find_envelope
from sampler.methods.probability import PRegion, PRegionEstimator
from sampler.methods.problem import Draw, Pilot, PilotPlan, Problem, ProgressFn, Run, Sampler
from sampler.methods.rare import RareResult, rare_probability
from sampler.methods.samplers import (
    SAMPLER_NAMES,
    SAMPLERS,
    AutoSampler,
    MCMCSampler,
    RejectionSampler,
    SubsetISSampler,
    SubsetSampler,
    make_sampler,
)
from sampler.methods.subset import SubsetResult, region_limit_state, subset_simulation

__all__ = [
    "SAMPLERS",
    "SAMPLER_NAMES",
    "AutoSampler",
    "Draw",
    "HalfSpace",
    "MCMCSampler",
    "PRegion",
    "PRegionEstimator",
    "Pilot",
    "PilotPlan",
    "Problem",
    "ProgressFn",
    "RareResult",
    "RejectionSampler",
    "Run",
    "Sampler",
    "SubsetISSampler",
    "SubsetResult",
    "SubsetSampler",
    "find_envelope",
    "make_sampler",
    "rare_probability",
    "region_limit_state",
    "subset_simulation",
]
