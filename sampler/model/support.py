"""How far a parameter vector lies outside what the model has seen: its density percentile.

``density_pct(x)`` is the share of the model's physical cut-ins (draws inside the physical
bounds) whose density is lower than that of ``x``:

    density_pct(x) = P( p(X) < p(x) | X physical ),  X ~ the model

0 for vectors less probable than every reference draw (deep extrapolation), about 0.5 for
a typical cut-in, near 1 at the mode. It is a constraint quantity like the others, so a
user caps extrapolation with e.g. ``density_pct > 0.001``: leave out the samples less
probable than all but 0.1 % of real cut-ins as the model sees them. Rare regions (``ttc <
3``) live in the tail, so their samples have small values; the cap says how deep into the
tail, beyond the data, a catalogue may go.

The reference is ``N_REFERENCE`` draws of the model (a fixed seed, so deterministic) inside
the physical bounds at the model's lane width, their log-densities sorted once per model
object (about 0.2 s); ``density_pct`` is the rank of ``log p(x)`` among them over their
number (resolution ``1 / N_REFERENCE``). The densities are those of the parameters in
original units (``CutInGMM.log_density``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from datasets import PARAM_NAMES
from sampler.errors import ConstraintError
from sampler.model.memo import memoised
from sampler.region.constraints import Region

__all__ = ["N_REFERENCE", "density_percentile"]

FloatArray = NDArray[np.float64]

#: reference draws of the model behind the percentile
N_REFERENCE = 20_000
_SEED = 20261124


def _reference(model: Any) -> FloatArray:
    """Sorted log-densities of the model's reference draws inside the physical bounds
    (memoised on the model object: :mod:`sampler.model.memo`)."""

    def compute() -> FloatArray:
        rng = np.random.default_rng(_SEED)
        x = model.sample(N_REFERENCE, rng)
        inside = Region(lane_width=model.lane_width_).in_bounds(model.params_matrix(x))
        return np.sort(model.log_density(x[inside]))

    return np.asarray(memoised(model, "density_reference", compute), dtype=np.float64)


def density_percentile(model: Any, params: FloatArray) -> FloatArray:
    """``density_pct`` of full parameter vectors (n, 8) in ``PARAM_NAMES`` order."""
    missing = [f for f in model.features_ if f not in PARAM_NAMES]
    if missing:
        raise ConstraintError(f"density_pct: the model has features that are not cut-in "
                              f"parameters ({', '.join(missing)})")
    ref = _reference(model)
    cols = [PARAM_NAMES.index(f) for f in model.features_]
    lp = model.log_density(np.asarray(params, dtype=np.float64)[:, cols])
    out = np.searchsorted(ref, lp, side="left") / max(ref.size, 1)
    return np.asarray(np.where(np.isnan(lp), np.nan, out), dtype=np.float64)
