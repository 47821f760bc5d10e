"""The scenario model for the service: load, describe, and the dashboard's views of it (the one
fit path is ``app.services.models.fit_model``)."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from app import jsonconv
from app.errors import InvalidInput
from datasets import PARAM_NAMES
from sampler import CutInGMM

__all__ = ["FittedModel", "describe", "describe_model", "load_model", "marginal_density",
           "model_components", "model_draws", "model_features", "model_lane_width"]


@dataclass(frozen=True)
class FittedModel:
    model: CutInGMM
    model_json: str
    model_hash: str
    n_components: int
    bic_curve: list[dict[str, Any]]
    fit_report: dict[str, Any]


def describe(model: CutInGMM) -> FittedModel:
    """A fitted model with its JSON, hash, BIC curve and fit report (what is stored)."""
    text = model.to_json()
    return FittedModel(
        model=model,
        model_json=text,
        model_hash=hashlib.sha256(text.encode()).hexdigest(),
        n_components=int(model.n_components_),
        bic_curve=jsonconv.encode(list(getattr(model, "bic_curve_", None) or [])),
        fit_report=jsonconv.encode(dict(getattr(model, "fit_report_", None) or {})),
    )


def load_model(model_json: str) -> CutInGMM:
    return CutInGMM.from_json(model_json)


def describe_model(model_json: str) -> FittedModel:
    return describe(load_model(model_json))


def model_components(model: CutInGMM) -> list[dict[str, Any]]:
    """Weight, mean and covariance of each mixture component, in the model's z-space
    (each feature transformed and standardised; see the model's ``transforms``)."""
    weights = np.asarray(model.weights_, dtype=np.float64)
    means = np.asarray(model.means_, dtype=np.float64)
    covs = np.asarray(model.covariances_, dtype=np.float64)
    names = model_features(model)
    return [{"weight": float(weights[k]),
             "mean_z": {n: float(m) for n, m in zip(names, means[k], strict=False)},
             "covariance_z": covs[k].tolist() if covs.size else None}
            for k in range(len(weights))]


def model_lane_width(model: CutInGMM) -> float:
    """The lane width (m) the model's region and scenarios use."""
    return float(model.lane_width_)


def model_features(model: CutInGMM) -> list[str]:
    """The parameters the model's mixture covers (the others are held at fixed values)."""
    return [str(f) for f in model.features_]


def marginal_density(model: CutInGMM, feature: str, x: ArrayLike) -> NDArray[np.float64]:
    """The model's marginal density of one feature in original units at the points ``x``.

    Exact from the mixture: the transforms are element-wise, so the marginal of feature j
    is ``sum_k w_k N(z_j; mu_kj, S_kjj) |dz_j/dx_j|`` (the marginal of a Gaussian mixture
    is the mixture of the components' marginals). Points outside the transform's domain
    get density 0. Raises InvalidInput for a non-feature.
    """
    xs = np.asarray(x, dtype=np.float64)
    names = model_features(model)
    if feature not in names:
        raise InvalidInput(f"{feature!r} is not a feature of the model ({', '.join(names)})",
                           field="query.feature")
    j = names.index(feature)
    z, logj = model.transforms_[j].forward(xs)
    weights = np.asarray(model.weights_, dtype=np.float64)
    mu = np.asarray(model.means_, dtype=np.float64)[:, j]
    var = np.asarray(model.covariances_, dtype=np.float64)[:, j, j]
    with np.errstate(invalid="ignore"):
        dens_z = np.sum(weights[:, None] * np.exp(-0.5 * (z[None, :] - mu[:, None]) ** 2
                                                  / var[:, None])
                        / np.sqrt(2.0 * math.pi * var[:, None]), axis=0)
        out = dens_z * np.exp(logj)
    return np.asarray(np.where(np.isfinite(out), out, 0.0), dtype=np.float64)


def model_draws(model: CutInGMM, n: int, seed: int) -> pd.DataFrame:
    """``n`` plain draws of the mixture (no region, no physical bounds), full parameter
    vectors with columns ``PARAM_NAMES``."""
    rng = np.random.default_rng(seed)
    x = model.sample(int(n), rng)
    return pd.DataFrame(model.params_matrix(x), columns=list(PARAM_NAMES))
