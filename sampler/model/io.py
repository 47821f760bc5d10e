"""JSON persistence of a ``CutInGMM`` (never pickle).

The file holds the features, transforms, weights, means, full covariances, the BIC curve,
the fit report, the training data's SHA-256 and size, and the scikit-learn version. Loading
recomputes the Cholesky factors from the stored covariances exactly as ``fit`` does, so the
loaded model's ``log_density`` equals the original's bit for bit.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import sklearn

from datasets import DEFAULT_LANE_WIDTH, PARAM_NAMES
from sampler.errors import ModelError
from sampler.model.support import check_support_dict
from sampler.model.transforms import FeatureTransform, transform_spec

if TYPE_CHECKING:
    from sampler.model.gmm import CutInGMM

__all__ = ["FORMAT", "model_from_dict", "model_to_dict"]

FORMAT = "scengen.cutin-gmm/1"


def model_to_dict(model: CutInGMM) -> dict[str, Any]:
    """JSON-able form of a fitted model (plain lists and numbers)."""
    model.check_fitted()
    return {
        "format": FORMAT,
        "features": list(model.features_),
        "transforms": [t.to_dict() for t in model.transforms_],
        "fixed": dict(model.fixed_),
        "lane_width": model.lane_width_,
        "n_components": model.n_components_,
        "covariance_type": model.covariance_type,
        "weights": model.weights_.tolist(),
        "means": model.means_.tolist(),
        "covariances": model.covariances_.tolist(),
        "bic_curve": list(getattr(model, "bic_curve_", [])),
        "fit_report": getattr(model, "fit_report_", None),
        "training": dict(getattr(model, "training_", {})),
        "sklearn_version": getattr(model, "sklearn_version_", sklearn.__version__),
        # issue 12: the data's exposure (sampler.rates.exposure) and the bootstrap replicates
        # (sampler.model.bootstrap); absent in older files
        "exposure": getattr(model, "exposure_", None),
        "bootstrap": getattr(model, "bootstrap_", None),
        "tail_calibration": getattr(model, "tail_calibration_", None),
        # issue 25: the training rows and the data-support rule (sampler.model.support);
        # absent in older files, which still load (without data support)
        "support": getattr(model, "support_", None),
        "settings": {"k_range": list(model.k_range), "n_init": model.n_init,
                     "reg_covar": model.reg_covar, "max_iter": model.max_iter,
                     "random_state": model.random_state, "cv_folds": model.cv_folds,
                     "n_report_samples": model.n_report_samples,
                     "lane_width": model.lane_width},
    }


def model_from_dict(cls: type[CutInGMM], data: Any) -> CutInGMM:
    """Rebuild a model of class ``cls`` from ``model_to_dict``'s form.

    Raises ModelError naming the bad field."""
    features = _checked_features(data)
    model = _new_model(cls, data, features)
    model.features_ = tuple(features)
    model.transforms_ = tuple(_transforms(data["transforms"], features))
    _set_mixture(model, data, len(features))
    fixed = data.get("fixed") or {}
    if not isinstance(fixed, Mapping):
        raise ModelError("fixed: expected an object")
    model.fixed_ = {str(k): float(v) for k, v in fixed.items()}
    missing = [p for p in PARAM_NAMES if p not in features and p not in model.fixed_]
    if missing:
        raise ModelError(f"fixed: missing value(s) for {', '.join(missing)}")
    lw = data.get("lane_width", DEFAULT_LANE_WIDTH)
    if isinstance(lw, bool) or not isinstance(lw, int | float) or not 0 < lw <= 10:
        raise ModelError(f"lane_width: must be a number in (0, 10] m, got {lw!r}")
    model.lane_width_ = float(lw)
    model.bic_curve_ = list(data.get("bic_curve") or [])
    if data.get("fit_report") is not None:
        model.fit_report_ = dict(data["fit_report"])
    model.training_ = dict(data.get("training") or {})
    model.sklearn_version_ = str(data.get("sklearn_version", "unknown"))
    _set_extras(model, data, features)
    return model


def _checked_features(data: Any) -> list[str]:
    """The form's features, after its envelope is checked (an object of this format with
    the mixture's keys)."""
    if not isinstance(data, Mapping):
        raise ModelError(f"model: expected a JSON object, got {type(data).__name__}")
    if data.get("format") != FORMAT:
        raise ModelError(f"format: expected {FORMAT!r}, got {data.get('format')!r}")
    for key in ("features", "transforms", "weights", "means", "covariances"):
        if key not in data:
            raise ModelError(f"{key}: missing")
    features = data["features"]
    if not isinstance(features, list) or not all(isinstance(f, str) for f in features):
        raise ModelError("features: expected a list of names")
    return features


def _new_model(cls: type[CutInGMM], data: Mapping[str, Any],
               features: list[str]) -> CutInGMM:
    """An unfitted ``cls`` with the form's settings."""
    settings = data.get("settings") or {}
    if not isinstance(settings, Mapping):
        raise ModelError("settings: expected an object")
    kwargs: dict[str, Any] = {
        k: (tuple(v) if k == "k_range" else v) for k, v in settings.items()
        if k in {"k_range", "n_init", "reg_covar", "max_iter", "random_state", "cv_folds",
                 "n_report_samples", "lane_width"}}
    try:
        return cls(features=features,
                   covariance_type=str(data.get("covariance_type", "full")), **kwargs)
    except TypeError as exc:
        raise ModelError(f"settings: {exc}") from None


def _transforms(trs: Any, features: list[str]) -> list[FeatureTransform]:
    """The features' transforms from the form's ``transforms`` (one object per feature)."""
    if not isinstance(trs, list) or len(trs) != len(features):
        raise ModelError("transforms: expected one entry per feature")
    transforms = []
    for i, (f, t) in enumerate(zip(features, trs, strict=True)):
        if not isinstance(t, Mapping) or t.get("feature") != f:
            raise ModelError(f"transforms[{i}]: expected an object for feature {f!r}")
        kind, shift = transform_spec(f, {"kind": t.get("kind"), "shift": t.get("shift", 0)})
        loc, scale = t.get("loc"), t.get("scale")
        if not (isinstance(loc, int | float) and isinstance(scale, int | float)
                and math.isfinite(loc) and math.isfinite(scale) and scale > 0):
            raise ModelError(f"transforms[{i}]: loc and scale must be finite, scale > 0")
        transforms.append(FeatureTransform(f, kind, shift, float(loc), float(scale)))
    return transforms


def _set_mixture(model: CutInGMM, data: Mapping[str, Any], d: int) -> None:
    """The form's weights, means and covariances (``d`` features) into ``model``."""
    try:
        weights = np.asarray(data["weights"], dtype=np.float64)
        means = np.asarray(data["means"], dtype=np.float64)
        covs = np.asarray(data["covariances"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"mixture: expected numeric arrays ({exc})") from None
    if means.ndim != 2 or means.shape[1] != d:
        raise ModelError(f"means: expected shape (K, {d}), got {means.shape}")
    model.set_mixture(weights, means, covs)


def _set_extras(model: CutInGMM, data: Mapping[str, Any], features: list[str]) -> None:
    """The optional parts (exposure, bootstrap, tail calibration, data support), checked,
    into ``model``."""
    for key in ("exposure", "bootstrap", "tail_calibration"):
        value = data.get(key)
        if value is not None and not isinstance(value, Mapping):
            raise ModelError(f"{key}: expected an object or null")
        if value is not None:
            setattr(model, f"{key}_", dict(value))
    boot = getattr(model, "bootstrap_", None)
    if boot is not None:
        _check_bootstrap(boot, len(features), int(model.n_components_))
    support = data.get("support")
    if support is not None:
        check_support_dict(support, features, model.training_.get("sha256"))
        model.support_ = dict(support)


def _check_bootstrap(boot: Mapping[str, Any], d: int, k: int) -> None:
    try:
        w = np.asarray(boot["weights"], dtype=np.float64)
        m = np.asarray(boot["means"], dtype=np.float64)
        c = np.asarray(boot["covariances"], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"bootstrap: expected weights, means, covariances ({exc})") from None
    b = w.shape[0] if w.ndim == 2 else -1
    if b < 1 or w.shape != (b, k) or m.shape != (b, k, d) or c.shape != (b, k, d, d):
        raise ModelError(f"bootstrap: shapes {w.shape}, {m.shape}, {c.shape} do not match "
                         f"K={k}, d={d}")
    if not (np.isfinite(w).all() and np.isfinite(m).all() and np.isfinite(c).all()):
        raise ModelError("bootstrap: replicates must be finite")
