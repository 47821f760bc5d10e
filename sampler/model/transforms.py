"""Per-feature transforms of the scenario model: a monotone map, then standardisation.

For every feature ``x`` the model works in ``z = (g(x) - loc) / scale`` where ``g`` is

=============  ======================  =================  ============================
kind           g(x)                    domain             log |dz/dx|
=============  ======================  =================  ============================
``identity``   x                       all reals          -log scale
``log``        log x                   x > 0              -log x - log scale
``log_shift``  log(x + shift)          x > -shift         -log(x + shift) - log scale
=============  ======================  =================  ============================

``loc`` and ``scale`` are the mean and standard deviation of ``g(x)`` over the training
data (z-scores), so every feature enters the mixture on the same scale. A density in
original units follows from the density of ``z`` by adding the log-Jacobian
``sum_j log |dz_j/dx_j|`` (the map is element-wise, so the Jacobian is diagonal).

Defaults (``DEFAULT_TRANSFORMS``): strictly positive quantities ``p_t``, ``p_v0`` and
``gap`` use ``log``; ``p_a3`` (a pulse duration, >= 0 but exactly 0 for cut-ins without a
pulse) uses ``log_shift`` with shift 0.1 s, so the zeros map to the finite value log 0.1
while long pulses are compressed; the model then puts a little mass on -0.1 < p_a3 < 0,
which the physical bound ``p_a3 >= 0`` removes (the fit report says how much). Signed
quantities (``p_y1``, ``p_a1``, ``p_a2``, ``dv``) use ``identity``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sampler.errors import ModelError

__all__ = ["DEFAULT_TRANSFORMS", "KINDS", "FeatureTransform", "transform_spec"]

FloatArray = NDArray[np.float64]

KINDS: tuple[str, ...] = ("identity", "log", "log_shift")

#: feature -> (kind, shift); features not listed use ("identity", 0.0)
DEFAULT_TRANSFORMS: dict[str, tuple[str, float]] = {
    "p_t": ("log", 0.0),
    "p_v0": ("log", 0.0),
    "gap": ("log", 0.0),
    "p_a3": ("log_shift", 0.1),
}


def transform_spec(feature: str, spec: Any = None) -> tuple[str, float]:
    """Normalise a user's transform spec: None (default), ``"log"``, ``("log_shift", 0.1)``
    or ``{"kind": "log_shift", "shift": 0.1}`` (a bare ``"log_shift"`` means shift 0.1)."""
    if spec is None:
        return DEFAULT_TRANSFORMS.get(feature, ("identity", 0.0))
    kind: Any
    shift: Any
    if isinstance(spec, str):
        kind, shift = spec, 0.1 if spec == "log_shift" else 0.0
    elif isinstance(spec, Mapping):
        kind, shift = spec.get("kind"), spec.get("shift", 0.0)
    elif isinstance(spec, tuple | list) and len(spec) == 2:
        kind, shift = spec
    else:
        raise ModelError(
            f"transforms.{feature}: expected a kind name or (kind, shift), got {spec!r}"
        )
    if kind not in KINDS:
        raise ModelError(f"transforms.{feature}: unknown kind {kind!r}; valid: {', '.join(KINDS)}")
    if isinstance(shift, bool) or not isinstance(shift, int | float) or not math.isfinite(shift):
        raise ModelError(f"transforms.{feature}: shift must be a finite number, got {shift!r}")
    if kind == "log_shift" and shift <= 0:
        raise ModelError(f"transforms.{feature}: log_shift needs shift > 0, got {shift}")
    return str(kind), float(shift) if kind == "log_shift" else 0.0


@dataclass(frozen=True)
class FeatureTransform:
    """``z = (g(x) - loc) / scale`` for one feature (see the module docstring)."""

    feature: str
    kind: str
    shift: float
    loc: float
    scale: float

    def g(self, x: FloatArray) -> FloatArray:
        """The monotone map; NaN outside its domain (no warning)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            if self.kind == "identity":
                return np.asarray(x, dtype=np.float64)
            arg = x if self.kind == "log" else x + self.shift
            return np.where(arg > 0, np.log(np.where(arg > 0, arg, 1.0)), np.nan)

    def forward(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``z`` and ``log |dz/dx|`` (``-inf`` and NaN outside the domain)."""
        y = self.g(x)
        z = (y - self.loc) / self.scale
        with np.errstate(invalid="ignore", divide="ignore"):
            if self.kind == "identity":
                logj = np.full(np.shape(x), -math.log(self.scale))
            else:
                logj = -y - math.log(self.scale)  # -log(arg) = -g(x)
        logj = np.where(np.isnan(y), -np.inf, logj)
        return z, logj

    def inverse(self, z: FloatArray) -> FloatArray:
        """Original units from ``z``."""
        y = z * self.scale + self.loc
        if self.kind == "identity":
            return y
        with np.errstate(over="ignore"):
            return np.exp(y) - self.shift if self.kind == "log_shift" else np.exp(y)

    def in_domain(self, x: FloatArray) -> NDArray[np.bool_]:
        """Where ``g`` is defined (and x is finite)."""
        if self.kind == "identity":
            return np.isfinite(x)
        arg = x if self.kind == "log" else x + self.shift
        return np.isfinite(x) & (arg > 0)

    def domain_text(self) -> str:
        return {"identity": "any finite number", "log": "> 0",
                "log_shift": f"> {-self.shift:g}"}[self.kind]

    def to_dict(self) -> dict[str, Any]:
        return {"feature": self.feature, "kind": self.kind, "shift": self.shift,
                "loc": self.loc, "scale": self.scale}
