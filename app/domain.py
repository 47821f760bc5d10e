"""The one place where the service calls the domain packages (datasets, sampler, riskcore).

Everything else in ``app`` goes through these functions, so integrating a change of a
domain package's API is a change here only. The domain packages are imported lazily: a
function whose domain code is missing raises ``DomainUnavailable`` (a
``NotImplementedError``) naming what is missing — never a made-up result.

Domain errors a user can cause (a malformed constraint, a bad parameter vector, a bad
uploaded file) come out as ``InvalidInput`` naming the field.
"""

from __future__ import annotations

import hashlib
import importlib
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from app.errors import DomainUnavailable, InvalidInput

#: the parameter vector's names (DESIGN.md); shared code that exists from the start
from datasets.cutin_model import PARAM_NAMES, ttc_from_gap_dv
from riskcore.scenario import ConcreteScenario, ScenarioError

__all__ = [
    "PARAM_NAMES",
    "FittedModel",
    "SampleResult",
    "build_scenario",
    "dataset_from_files",
    "embedded_parameter_table",
    "fit_model",
    "jsonable",
    "load_model",
    "parse_constraints",
    "sample",
    "score_posted",
    "score_scenario",
    "table_hash",
    "ttc_of",
    "versions",
]


def _need(module: str, attr: str | None = None) -> Any:
    """Import ``module`` (and get ``attr``) or raise DomainUnavailable naming it."""
    what = f"{module}.{attr}" if attr else module
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        raise DomainUnavailable(f"{what} is not available yet ({exc})") from None
    if attr is None:
        return mod
    try:
        return getattr(mod, attr)
    except AttributeError:
        raise DomainUnavailable(f"{what} is not available yet") from None


# --------------------------------------------------------------------------- JSON
def jsonable(value: Any) -> Any:
    """Plain JSON types: numpy scalars/arrays to Python, non-finite floats to None."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        x = float(value)
        return x if math.isfinite(x) else None
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, Path):
        return str(value)
    return str(value)


_NONFINITE = {"Infinity": math.inf, "-Infinity": -math.inf, "NaN": math.nan}


def encode_floats(value: Any) -> Any:
    """JSON for storage: like ``jsonable`` but non-finite floats become the strings
    ``"Infinity"``, ``"-Infinity"``, ``"NaN"`` so that ``decode_floats`` restores them."""
    if isinstance(value, Mapping):
        return {str(k): encode_floats(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [encode_floats(v) for v in value]
    if isinstance(value, float | np.floating) and not isinstance(value, bool):
        x = float(value)
        if math.isnan(x):
            return "NaN"
        if math.isinf(x):
            return "Infinity" if x > 0 else "-Infinity"
        return x
    return jsonable(value)


def decode_floats(value: Any) -> Any:
    """Inverse of ``encode_floats``."""
    if isinstance(value, dict):
        return {k: decode_floats(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_floats(v) for v in value]
    if isinstance(value, str) and value in _NONFINITE:
        return _NONFINITE[value]
    return value


def finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def versions() -> dict[str, str | None]:
    """Versions of scengen and the libraries whose numbers end in the results."""
    from importlib.metadata import PackageNotFoundError, version

    from app import __version__

    out: dict[str, str | None] = {"scengen": __version__}
    for name in ("numpy", "scipy", "pandas", "scikit-learn", "emcee", "numba", "fastapi",
                 "sqlalchemy", "distributed"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


# --------------------------------------------------------------------------- datasets
def embedded_parameter_table() -> pd.DataFrame:
    """The cut-in parameter table of the embedded TNO data (one row per cut-in)."""
    fn = _need("datasets.embedded", "default_parameter_table")
    table = fn()
    if not isinstance(table, pd.DataFrame):
        raise DomainUnavailable("datasets.embedded.default_parameter_table returned no table")
    return table


def table_hash(table: pd.DataFrame) -> str:
    """sha256 of a parameter table's content (columns, order, values): the data hash."""
    buf = io.StringIO()
    table.to_csv(buf, index=False, float_format="%.17g")
    return hashlib.sha256(buf.getvalue().encode()).hexdigest()


DATASET_KINDS = ("highd", "egocentric")


def dataset_from_files(kind: str, paths: Sequence[Path]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Read uploaded files of one dataset and extract its cut-in parameter table.

    ``kind`` is ``highd`` (a recording's ``*_tracks.csv``, ``*_tracksMeta.csv`` and
    ``*_recordingMeta.csv``) or ``egocentric`` (one CSV or Parquet file). Returns the table
    and a report (counts, dropped events). Bad files raise InvalidInput.
    """
    if kind not in DATASET_KINDS:
        raise InvalidInput(f"unknown dataset kind {kind!r}; choose one of "
                           f"{', '.join(DATASET_KINDS)}", field="body.kind")
    raise DomainUnavailable(f"reading {kind} uploads: datasets readers are not integrated yet")


# --------------------------------------------------------------------------- models
@dataclass(frozen=True)
class FittedModel:
    model: Any
    model_json: str
    model_hash: str
    n_components: int
    bic_curve: list[dict[str, Any]]
    fit_report: dict[str, Any]


def fit_model(table: pd.DataFrame, options: Mapping[str, Any]) -> FittedModel:
    """Fit the cut-in GMM on a parameter table with the sampler's options."""
    cls = _need("sampler.model", "CutInGMM")
    try:
        model = cls(**dict(options))
    except TypeError as exc:
        raise InvalidInput(f"model options: {exc}", field="body.options") from None
    try:
        model.fit(table)
    except ValueError as exc:
        raise InvalidInput(f"fitting the model failed: {exc}", field="body.options") from None
    return _describe(model)


def _describe(model: Any) -> FittedModel:
    text = model.to_json()
    return FittedModel(
        model=model,
        model_json=text,
        model_hash=hashlib.sha256(text.encode()).hexdigest(),
        n_components=int(getattr(model, "n_components_", 0) or 0),
        bic_curve=jsonable(list(getattr(model, "bic_curve_", []) or [])),
        fit_report=jsonable(dict(getattr(model, "fit_report_", {}) or {})),
    )


def load_model(model_json: str) -> Any:
    cls = _need("sampler.model", "CutInGMM")
    return cls.from_json(model_json)


def describe_model(model_json: str) -> FittedModel:
    return _describe(load_model(model_json))


def model_components(model: Any) -> list[dict[str, Any]]:
    """Weights, means and covariances of the mixture's components (parameter order)."""
    weights = np.asarray(getattr(model, "weights_", []), dtype=float)
    means = np.asarray(getattr(model, "means_", []), dtype=float)
    covs = np.asarray(getattr(model, "covariances_", []), dtype=float)
    names = list(getattr(model, "feature_names_", PARAM_NAMES))
    out = []
    for k in range(len(weights)):
        out.append({
            "weight": float(weights[k]),
            "mean": {n: float(m) for n, m in zip(names, means[k], strict=False)},
            "covariance": jsonable(covs[k]) if covs.size else None,
        })
    return out


# --------------------------------------------------------------------------- sampling
def parse_constraints(texts: Sequence[str], field: str = "body.constraints") -> list[Any]:
    parse = _need("sampler.constraints", "parse_constraint")
    out = []
    for i, text in enumerate(texts):
        try:
            out.append(parse(text))
        except ValueError as exc:
            raise InvalidInput(f"constraint {text!r}: {exc}", field=f"{field}.{i}") from None
    return out


@dataclass(frozen=True)
class SampleResult:
    """What the service keeps of a sampler SampleSet."""

    params: pd.DataFrame  # columns PARAM_NAMES, one row per sample
    weights: np.ndarray  # exposure weight per sample
    p_region: dict[str, Any]  # {"estimate", "ci": [lo, hi], ...}
    diagnostics: dict[str, Any]


def sample(model: Any, constraints: Sequence[Any], n: int, seed: int,
           method: str = "auto") -> SampleResult:
    fn = _need("sampler", "sample")
    try:
        ss = fn(model, constraints, n, seed, method=method)
    except ValueError as exc:
        raise InvalidInput(f"sampling failed: {exc}", field="body") from None
    raise DomainUnavailable(f"adapter for SampleSet not written yet ({type(ss).__name__})")


def estimate_region(model: Any, constraints: Sequence[Any], seed: int) -> dict[str, Any]:
    """P(A) of the constraint region under the model: ``{"estimate", "ci": [lo, hi], ...}``."""
    raise DomainUnavailable("P(A) estimation: sampler integration is not written yet")


def ttc_of(params: Mapping[str, float]) -> float:
    return float(ttc_from_gap_dv(params["gap"], params["dv"]))


# --------------------------------------------------------------------------- scenarios
def build_scenario(params: Mapping[str, float], seed: int) -> ConcreteScenario:
    fn = _need("sampler.builder", "build_scenario")
    result: ConcreteScenario = fn(dict(params), seed=seed)
    return result


def score_scenario(scenario: ConcreteScenario) -> dict[str, Any]:
    """The flat risk summary of one scenario (riskcore ``ScenarioRisk.summary()``)."""
    fn = _need("riskcore", "evaluate_scenario")
    risk = fn(scenario)
    return dict(risk.summary())


def score_posted(data: Any) -> dict[str, Any]:
    """Score a posted concrete scenario (its JSON form) → per-step series and summary."""
    try:
        scenario = ConcreteScenario.from_dict(data)
    except ScenarioError as exc:
        raise InvalidInput(str(exc), field=_scenario_field(str(exc))) from None
    fn = _need("riskcore", "evaluate_scenario")
    risk = fn(scenario)
    return {"summary": jsonable(dict(risk.summary())), "risk": jsonable(risk.to_dict())}


def _scenario_field(message: str) -> str:
    head = message.split(":", 1)[0].strip()
    if not head or " " in head:
        return "body"
    return f"body.{head}"


# --------------------------------------------------------------------------- dashboard
# Added for the dashboard (issue 6): read-only views of a model and of a scenario's risk.
def model_features(model: Any) -> list[str]:
    """The parameters the model's mixture covers (the others are held at fixed values)."""
    return [str(f) for f in getattr(model, "features_", PARAM_NAMES)]


def marginal_density(model: Any, feature: str, x: Any) -> np.ndarray:
    """The model's marginal density of one feature in original units at the points ``x``.

    Uses the model's own ``marginal_log_density(feature, x)`` when it has one. Otherwise it
    is computed exactly from the mixture: the transforms are element-wise, so the marginal
    of feature j is ``sum_k w_k N(z_j; mu_kj, S_kjj) |dz_j/dx_j|`` (the marginal of a
    Gaussian mixture is the mixture of the components' marginals). Points outside the
    transform's domain get density 0. Raises InvalidInput for a non-feature.
    """
    xs = np.asarray(x, dtype=np.float64)
    own = getattr(model, "marginal_log_density", None)
    if callable(own):
        return np.exp(np.asarray(own(feature, xs), dtype=np.float64))
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
    return np.where(np.isfinite(out), out, 0.0)


def model_draws(model: Any, n: int, seed: int) -> pd.DataFrame:
    """``n`` plain draws of the mixture (no region, no physical bounds), full parameter
    vectors with columns ``PARAM_NAMES``."""
    rng = np.random.default_rng(seed)
    x = model.sample(int(n), rng)
    return pd.DataFrame(model.params_matrix(x), columns=list(PARAM_NAMES))


def scenario_risk_series(scenario: ConcreteScenario) -> dict[str, Any]:
    """A scenario's risk summary and per-step series (``t``, ``r_dep``, ``r_ind``,
    ``min_ttr``, ``ttc``, ``wttc``, ``thw``; +inf as None) without the Monte-Carlo samples."""
    fn = _need("riskcore", "evaluate_scenario")
    risk = fn(scenario)
    series: dict[str, Any] = {"t": np.asarray(risk.t, dtype=np.float64)}
    for name in ("r_dep", "r_ind", "min_ttr", "ttc", "wttc", "thw"):
        series[name] = risk.series(name)
    return {"summary": jsonable(dict(risk.summary())), "series": jsonable(series)}
