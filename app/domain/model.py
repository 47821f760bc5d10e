"""The scenario model for the service: fit, load, describe, and the dashboard's views of it."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from app import jsonconv
from app.errors import InvalidInput
from datasets import EMBEDDED_SOURCE, PARAM_NAMES
from sampler import CutInGMM, SamplerError
from sampler.model import bootstrap_fit
from sampler.rates import Exposure, tno_exposure

__all__ = ["FittedModel", "describe_model", "fit_model", "load_model", "marginal_density",
           "model_components", "model_draws", "model_features", "model_lane_width"]


@dataclass(frozen=True)
class FittedModel:
    model: CutInGMM
    model_json: str
    model_hash: str
    n_components: int
    bic_curve: list[dict[str, Any]]
    fit_report: dict[str, Any]


def fit_model(table: pd.DataFrame, options: Mapping[str, Any],
              source: str | None = None,
              exposure: Mapping[str, Any] | None = None) -> FittedModel:
    """Fit the cut-in GMM on a parameter table with the sampler's options. ``exposure``:
    the dataset's (``sampler.rates.exposure.Exposure`` as a dict), carried into the model; the
    embedded TNO table gets its 63 hours."""
    kwargs = dict(options)
    n_boot = kwargs.pop("n_bootstrap", 100)  # issue 12: the model interval's refits
    if isinstance(n_boot, bool) or not isinstance(n_boot, int) or n_boot == 1 or n_boot < 0:
        raise InvalidInput(f"n_bootstrap: expected 0 or 2 ... 10000 refits, got {n_boot!r}",
                           field="body.options.n_bootstrap")
    if isinstance(kwargs.get("k_range"), list):
        kwargs["k_range"] = tuple(kwargs["k_range"])
    try:
        model = CutInGMM(**kwargs)
    except (TypeError, SamplerError) as exc:
        raise InvalidInput(f"model options: {exc}", field="body.options") from None
    try:
        model.fit(table, source=source)
        if n_boot:
            bootstrap_fit(model, table, n_boot, seed=int(model.random_state))
    except ValueError as exc:
        raise InvalidInput(f"fitting the model failed: {exc}", field="body.options") from None
    if exposure is not None:
        model.exposure_ = Exposure.from_dict({**exposure, "n_events": len(table)}).to_dict()
    elif "source" in table.columns and (table["source"] == EMBEDDED_SOURCE).all():
        model.exposure_ = tno_exposure(len(table)).to_dict()  # 63 h (de Gelder et al. 2021)
    return describe(model)


def describe(model: CutInGMM) -> FittedModel:
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
