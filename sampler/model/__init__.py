"""The cut-in model: a Gaussian mixture over transformed cut-in parameters.

- :mod:`~sampler.model.gmm` — :class:`CutInGMM` (fit, densities, draws, the z-space
  interface the sampling methods use: ``to_z``/``from_z``, ``log_density_z``,
  ``sample_z``, ``cholesky``, ``cdf_z``, ``set_mixture``, ``check_fitted``);
- :mod:`~sampler.model.transforms` — per-feature monotone maps and standardisation;
- :mod:`~sampler.model.io` — JSON persistence (never pickle);
- :mod:`~sampler.model.fit_report` — held-out fit checks and ``scengen fit``'s text;
- :mod:`~sampler.model.bootstrap` — bootstrap refits (the model's own uncertainty);
- :mod:`~sampler.model.memo` — quantities kept on a fitted model object;
- :mod:`~sampler.model.support` — how far a vector lies from what the model has seen.
"""

from sampler.model.bootstrap import bootstrap_fit, log_density_z_boot, pooled_model, replicate_model
from sampler.model.gmm import CutInGMM
from sampler.model.memo import memoised
from sampler.model.support import CLASSES as SUPPORT_CLASSES
from sampler.model.support import density_percentile
from sampler.model.transforms import DEFAULT_TRANSFORMS, FeatureTransform, transform_spec

__all__ = [
    "DEFAULT_TRANSFORMS",
    "SUPPORT_CLASSES",
    "CutInGMM",
    "FeatureTransform",
    "bootstrap_fit",
    "density_percentile",
    "log_density_z_boot",
    "memoised",
    "pooled_model",
    "replicate_model",
    "transform_spec",
]
