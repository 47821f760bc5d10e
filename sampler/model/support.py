"""What the data support: how far a parameter vector lies from the real cut-ins the model
was fitted on.

A model fitted to a few hundred real cut-ins is asked about regions (``ttc < 3``) where it
saw none: it extrapolates. This module says, for every vector, by how much and where
(docs/sampler.md, "Data support", has the definitions, the thresholds and the figures):

* **per parameter** (``support_outside``): the model features that lie outside the range
  ``[min, max]`` of the training data, the excess in the parameter's unit (signed: + above
  the largest value seen, - below the smallest) and relative to the data's spread
  (``|excess| / sd``, ``sd`` the sample standard deviation of the column, ``ddof = 1``);
  ``support_excess`` is the largest relative excess over the features (0: inside every
  range);
* **joint**: ``support_distance``, the Euclidean distance to the nearest training row in
  the model's standardised transformed space z (each feature mapped by the model's
  transform ``g`` and standardised by the data's mean and standard deviation of ``g``, so
  one unit is one standard deviation of one transformed parameter over the data; the
  training rows themselves have mean 0 and standard deviation 1 in every coordinate), and
  ``density_pct`` (below), the model's own view;
* **class** (``support``): ``inside`` when every feature lies within the data's range and
  ``support_distance <= d_inside``; else ``near`` when every feature lies within the range
  widened by ``near_excess_sd`` standard deviations on both sides and
  ``support_distance <= d_near``; else ``extrapolated``. ``d_inside`` and ``d_near`` are the
  ``inside_quantile`` (0.95) and ``near_quantile`` (0.99) quantiles of the training rows'
  leave-one-out nearest-neighbour distances (each row's distance to the nearest *other*
  row): a vector is "inside" when it is as close to a real cut-in as 95 % of the real
  cut-ins are to one another. ``near_excess_sd`` is 0.5 (docs: of the 13 TNO rows that lie
  outside the range of the other 207, 9 do so by less than 0.5 sd). Classes are ordered,
  codes 0, 1, 2 (``CLASSES``), so that ``support != extrapolated`` is ``support < 2``.

The model carries what this needs (``CutInGMM.support_``, persisted in its JSON by
:mod:`sampler.model.io`): the training rows in original units and the rule's three
constants. Everything else (ranges, spreads, z, the leave-one-out distances, the
thresholds, a k-d tree) is derived from them once per model object (memoised). The rows'
SHA-256 must equal the model's training hash, so the points are the data it was fitted on.
Model files written before this (no ``support``) still load; :func:`attach_support` adds the
rows from the training table (checked against the hash), and the support measures of such a
model raise :class:`~sampler.errors.ModelError` saying so.

``density_pct(x)`` is the share of the model's physical cut-ins (draws inside the physical
bounds) whose density is lower than that of ``x``:

    density_pct(x) = P( p(X) < p(x) | X physical ),  X ~ the model

0 for vectors less probable than every reference draw (deep extrapolation), about 0.5 for
a typical cut-in, near 1 at the mode. The reference is ``N_REFERENCE`` draws of the model (a
fixed seed, so deterministic) inside the physical bounds at the model's lane width, their
log-densities sorted once per model object (about 0.2 s); ``density_pct`` is the rank of
``log p(x)`` among them over their number (resolution ``1 / N_REFERENCE``). The densities are
those of the parameters in original units (``CutInGMM.log_density``).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from datasets import PARAM_NAMES, PARAM_UNITS
from sampler.errors import ConstraintError, ModelError
from sampler.model.memo import memoised
from sampler.region.constraints import Region

__all__ = [
    "CLASSES",
    "INSIDE_QUANTILE",
    "NEAR_EXCESS_SD",
    "NEAR_QUANTILE",
    "N_REFERENCE",
    "SUPPORT_FORMAT",
    "SupportMeasures",
    "TrainingSupport",
    "attach_support",
    "density_percentile",
    "support_dict",
    "support_margin",
    "support_measures",
    "training_support",
]

FloatArray = NDArray[np.float64]

#: reference draws of the model behind the percentile
N_REFERENCE = 20_000
_SEED = 20261124

SUPPORT_FORMAT = "scengen.support/1"
#: the classes in order: a vector's code is its position
CLASSES: tuple[str, ...] = ("inside", "near", "extrapolated")
#: the rule's defaults (docs/sampler.md, "Data support": why these)
INSIDE_QUANTILE = 0.95
NEAR_QUANTILE = 0.99
NEAR_EXCESS_SD = 0.5


# ---------------------------------------------------------------------------- density


def _reference(model: Any) -> FloatArray:
    """Sorted log-densities of the model's reference draws inside the physical bounds
    (memoised on the model object: :mod:`sampler.model.memo`)."""

    def compute() -> FloatArray:
        rng = np.random.default_rng(_SEED)
        x = model.sample(N_REFERENCE, rng)
        inside = Region(lane_width=model.lane_width_).in_bounds(model.params_matrix(x))
        return np.sort(model.log_density(x[inside]))

    return np.asarray(memoised(model, "density_reference", compute), dtype=np.float64)


def _feature_columns(model: Any, what: str) -> list[int]:
    missing = [f for f in model.features_ if f not in PARAM_NAMES]
    if missing:
        raise ConstraintError(f"{what}: the model has features that are not cut-in "
                              f"parameters ({', '.join(missing)})")
    return [PARAM_NAMES.index(f) for f in model.features_]


def density_percentile(model: Any, params: FloatArray) -> FloatArray:
    """``density_pct`` of full parameter vectors (n, 8) in ``PARAM_NAMES`` order."""
    cols = _feature_columns(model, "density_pct")
    ref = _reference(model)
    lp = model.log_density(np.asarray(params, dtype=np.float64)[:, cols])
    out = np.searchsorted(ref, lp, side="left") / max(ref.size, 1)
    return np.asarray(np.where(np.isnan(lp), np.nan, out), dtype=np.float64)


# ---------------------------------------------------------------------------- the rows


def _rows_hash(points: FloatArray, features: Sequence[str]) -> str:
    """SHA-256 of the feature names and the float64 matrix: ``CutInGMM``'s training hash."""
    h = hashlib.sha256(json.dumps(list(features)).encode())
    h.update(np.ascontiguousarray(points, dtype="<f8").tobytes())
    return h.hexdigest()


def support_dict(points: FloatArray, features: Sequence[str], *,
                 inside_quantile: float = INSIDE_QUANTILE,
                 near_quantile: float = NEAR_QUANTILE,
                 near_excess_sd: float = NEAR_EXCESS_SD) -> dict[str, Any]:
    """The JSON form kept in a model (``CutInGMM.support_``): the training rows (original
    units, columns ``features``) and the rule's constants."""
    pts = np.asarray(points, dtype=np.float64)
    return {"format": SUPPORT_FORMAT, "features": list(features), "points": pts.tolist(),
            "rule": {"inside_quantile": float(inside_quantile),
                     "near_quantile": float(near_quantile),
                     "near_excess_sd": float(near_excess_sd)}}


def check_support_dict(data: Any, features: Sequence[str], sha256: str | None) -> None:
    """Raise :class:`ModelError` naming the field when a model's ``support`` entry is
    malformed or its rows are not the training data (their hash differs from the model's
    training hash ``sha256``; None: not checked)."""
    if not isinstance(data, Mapping):
        raise ModelError("support: expected an object")
    if data.get("format") != SUPPORT_FORMAT:
        raise ModelError(f"support.format: expected {SUPPORT_FORMAT!r}, got "
                         f"{data.get('format')!r}")
    if list(data.get("features") or []) != list(features):
        raise ModelError(f"support.features: expected the model's features {list(features)}")
    try:
        pts = np.asarray(data.get("points"), dtype=np.float64)
    except (TypeError, ValueError):
        raise ModelError("support.points: expected a numeric matrix") from None
    if pts.ndim != 2 or pts.shape[1] != len(features) or pts.shape[0] < 2:
        raise ModelError(f"support.points: expected shape (n >= 2, {len(features)}), got "
                         f"{pts.shape}")
    if not np.isfinite(pts).all():
        raise ModelError("support.points: must be finite")
    rule = data.get("rule")
    if not isinstance(rule, Mapping):
        raise ModelError("support.rule: expected an object")
    for key, lo, hi in (("inside_quantile", 0.0, 1.0), ("near_quantile", 0.0, 1.0),
                        ("near_excess_sd", 0.0, math.inf)):
        v = rule.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
            raise ModelError(f"support.rule.{key}: expected a number in [{lo}, {hi}], "
                             f"got {v!r}")
    if rule["inside_quantile"] > rule["near_quantile"]:
        raise ModelError("support.rule: inside_quantile must not exceed near_quantile")
    if sha256 is not None and _rows_hash(pts, features) != sha256:
        raise ModelError("support.points: not the training data (their SHA-256 differs from "
                         "training.sha256)")


def attach_support(model: Any, table: Any) -> None:
    """Give a model that has no training rows (a file written before data support) the rows
    of ``table``, its training table; raises :class:`ModelError` unless their hash equals
    the model's training hash."""
    model.check_fitted()
    x = model.table_matrix(table, model.features_, where="support table")
    sha = (getattr(model, "training_", None) or {}).get("sha256")
    if sha is None or _rows_hash(x, model.features_) != sha:
        raise ModelError("support: the table is not the model's training data (its SHA-256 "
                         "differs from training.sha256); refit the model on it instead")
    model.support_ = support_dict(x, model.features_)
    model.__dict__.get("_scengen_memo", {}).pop("support", None)


@dataclass(frozen=True)
class TrainingSupport:
    """What the support measures need, derived from a model's training rows."""

    features: tuple[str, ...]
    points: FloatArray  # (n, d) original units
    z: FloatArray  # (n, d) the model's z-space
    lo: FloatArray  # (d,) smallest value of each feature
    hi: FloatArray  # (d,) largest
    sd: FloatArray  # (d,) sample standard deviation (ddof 1), original units
    loo: FloatArray  # (n,) leave-one-out nearest-neighbour distances in z
    d_inside: float
    d_near: float
    inside_quantile: float
    near_quantile: float
    near_excess_sd: float
    tree: Any  # scipy.spatial.cKDTree over z

    def summary(self) -> dict[str, Any]:
        """The figures behind the thresholds (docs, ``scengen fit``, ``GET /models``)."""
        qs = (0.5, 0.9, 0.95, 0.99, 1.0)
        return {
            "n_rows": int(self.points.shape[0]),
            "distance": "Euclidean in the model's standardised transformed space z",
            "d_inside": self.d_inside, "d_near": self.d_near,
            "inside_quantile": self.inside_quantile, "near_quantile": self.near_quantile,
            "near_excess_sd": self.near_excess_sd,
            "leave_one_out": {f"q{round(q * 100)}": float(np.quantile(self.loo, q))
                              for q in qs},
            "ranges": {f: {"min": float(self.lo[j]), "max": float(self.hi[j]),
                           "sd": float(self.sd[j]), "unit": PARAM_UNITS.get(f, "")}
                       for j, f in enumerate(self.features)},
        }


def training_support(model: Any) -> TrainingSupport:
    """The model's :class:`TrainingSupport` (memoised on the model object); raises
    :class:`ModelError` when the model carries no training rows."""
    data = getattr(model, "support_", None)
    if data is None:
        raise ModelError("this model carries no training rows, so the data support cannot be "
                         "measured (a model file written before data support): refit it "
                         "(scengen fit) or attach its table (sampler.model.support."
                         "attach_support)")

    def compute() -> TrainingSupport:
        pts = np.asarray(data["points"], dtype=np.float64)
        rule = data["rule"]
        z = model.to_z(pts)
        tree = cKDTree(z)
        dist, _ = tree.query(z, k=2)
        loo = np.asarray(dist[:, 1], dtype=np.float64)
        return TrainingSupport(
            features=tuple(model.features_), points=pts, z=z, lo=pts.min(axis=0),
            hi=pts.max(axis=0), sd=pts.std(axis=0, ddof=1), loo=loo,
            d_inside=float(np.quantile(loo, rule["inside_quantile"])),
            d_near=float(np.quantile(loo, rule["near_quantile"])),
            inside_quantile=float(rule["inside_quantile"]),
            near_quantile=float(rule["near_quantile"]),
            near_excess_sd=float(rule["near_excess_sd"]), tree=tree)

    out: TrainingSupport = memoised(model, "support", compute)
    return out


# ---------------------------------------------------------------------------- measures


@dataclass(frozen=True)
class SupportMeasures:
    """The support of n vectors (arrays of shape (n,), ``excess`` (n, d))."""

    features: tuple[str, ...]
    code: FloatArray  # 0 inside, 1 near, 2 extrapolated (NaN: a NaN vector)
    distance: FloatArray  # to the nearest training row, z-space (+inf: outside a transform)
    nearest: NDArray[np.int64]  # that row's index in the training table (-1: none)
    excess: FloatArray  # signed excess beyond the data's range, original units (0 inside)
    excess_sd: FloatArray  # |excess| / sd, (n, d)
    largest: FloatArray  # max of excess_sd over the features
    density_pct: FloatArray | None = None

    def classes(self) -> list[str | None]:
        return [None if math.isnan(c) else CLASSES[int(c)] for c in self.code.tolist()]

    def outside(self, i: int) -> list[dict[str, Any]]:
        """Vector i's features outside the data's range: ``name``, ``excess`` (unit),
        ``excess_sd``, ``unit``, largest relative excess first."""
        out = [{"name": f, "excess": float(self.excess[i, j]),
                "excess_sd": float(self.excess_sd[i, j]), "unit": PARAM_UNITS.get(f, "")}
               for j, f in enumerate(self.features) if self.excess[i, j] != 0.0]
        return sorted(out, key=lambda o: (-o["excess_sd"], o["name"]))

    def record(self, i: int) -> dict[str, Any]:
        """Vector i's support as the fields of a scenario record."""
        code = self.code[i]
        dp = None if self.density_pct is None else float(self.density_pct[i])
        return {"support": None if math.isnan(code) else CLASSES[int(code)],
                "support_distance": float(self.distance[i]),
                "support_excess": float(self.largest[i]),
                "support_nearest": int(self.nearest[i]) if self.nearest[i] >= 0 else None,
                "density_pct": None if dp is None or math.isnan(dp) else dp,
                "support_outside": self.outside(i)}

    def shares(self) -> dict[str, int]:
        """How many vectors of each class (every class, zeros included)."""
        valid = self.code[~np.isnan(self.code)].astype(int)
        return {c: int((valid == k).sum()) for k, c in enumerate(CLASSES)}


def support_measures(model: Any, params: FloatArray, *, with_density: bool = False
                     ) -> SupportMeasures:
    """The support of full parameter vectors (n, 8) in ``PARAM_NAMES`` order (module
    docstring). ``with_density`` adds ``density_pct``."""
    ts = training_support(model)
    cols = _feature_columns(model, "support")
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 1:
        p = p[None, :]
    x = p[:, cols]
    n = x.shape[0]
    with np.errstate(invalid="ignore"):
        excess = np.where(x > ts.hi, x - ts.hi, np.where(x < ts.lo, x - ts.lo, 0.0))
        excess_sd = np.abs(excess) / ts.sd
    nan_row = np.isnan(x).any(axis=1)
    excess[nan_row] = np.nan
    excess_sd[nan_row] = np.nan
    largest = np.max(excess_sd, axis=1) if n else np.zeros(0)
    z = model.to_z(x) if n else np.zeros((0, x.shape[1]))
    finite = np.isfinite(z).all(axis=1)
    distance = np.full(n, np.inf)
    nearest = np.full(n, -1, dtype=np.int64)
    if finite.any():
        d, k = ts.tree.query(z[finite], k=1)
        distance[finite] = d
        nearest[finite] = k
    distance[nan_row] = np.nan
    code = np.where(
        (largest <= 0.0) & (distance <= ts.d_inside), 0.0,
        np.where((largest <= ts.near_excess_sd) & (distance <= ts.d_near), 1.0, 2.0))
    code[nan_row] = np.nan
    dp = density_percentile(model, p) if with_density else None
    return SupportMeasures(features=ts.features, code=code, distance=distance,
                           nearest=nearest, excess=excess, excess_sd=excess_sd,
                           largest=largest, density_pct=dp)


def support_margin(model: Any, distance: FloatArray, largest: FloatArray, op: str,
                   value: float) -> FloatArray:
    """A continuous margin of the constraint ``support op value`` on the class codes:
    <= 0 exactly where the constraint holds, > 0 where it does not (the limit state of
    subset simulation needs one: the codes are flat). ``distance`` and ``largest`` are
    ``support_distance`` and ``support_excess``.

    ``code <= 0`` (inside) is ``distance / d_inside - 1 <= 0`` where ``largest`` is 0 and
    ``max(largest / e, distance / d_inside - 1)`` (> 0) where it is not;
    ``code <= 1`` (not extrapolated) is ``max(largest / e - 1, distance / d_near - 1) <= 0``
    (``e`` = ``near_excess_sd``); a lower limit is the negation of the one below it, with
    a margin of 0 moved to the outside."""
    ts = training_support(model)
    e = max(ts.near_excess_sd, 1e-12)
    d = np.asarray(distance, dtype=np.float64)
    r = np.asarray(largest, dtype=np.float64)

    def at_most(k: int) -> FloatArray:
        if k < 0:
            return np.ones_like(d)
        if k >= len(CLASSES) - 1:
            return -np.ones_like(d)
        with np.errstate(invalid="ignore", divide="ignore"):
            if k == 0:  # r > 0 is outside whatever d; with r = 0, d alone decides
                m = np.where(r > 0.0, np.maximum(r / e, d / ts.d_inside - 1.0),
                             d / ts.d_inside - 1.0)
            else:
                m = np.maximum(r / e - 1.0, d / ts.d_near - 1.0)
        return np.asarray(m, dtype=np.float64)

    if op in ("<", "<="):
        k = math.ceil(value) - 1 if op == "<" else math.floor(value)
        return at_most(int(k))
    lo = math.floor(value) + 1 if op == ">" else math.ceil(value)
    m = -at_most(int(lo) - 1)
    tiny = float(np.finfo(np.float64).tiny)
    return np.asarray(np.where(m == 0.0, tiny, m), dtype=np.float64)
