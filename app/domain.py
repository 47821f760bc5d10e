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
import json
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


#: modules whose code turns the embedded events into the parameter table
_EXTRACTION_MODULES = ("datasets.cutin_model", "datasets.egocentric", "datasets.extract",
                       "datasets.embedded")


def embedded_source_hash() -> str:
    """sha256 of the embedded events file and of the extraction code: the key of the
    cached embedded parameter table (extraction takes tens of seconds)."""
    path = _need("datasets.embedded", "DEFAULT_EVENTS_PATH")
    digest = hashlib.sha256()
    try:
        digest.update(Path(path).read_bytes())
        for name in _EXTRACTION_MODULES:
            digest.update(Path(_need(name).__file__).read_bytes())
    except OSError as exc:
        raise DomainUnavailable(f"embedded data not readable: {exc}") from None
    return digest.hexdigest()


def options_hash(options: Mapping[str, Any]) -> str:
    return hashlib.sha256(json.dumps(jsonable(options), sort_keys=True).encode()).hexdigest()


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
    extract = _need("datasets.extract", "extract_cutins")
    if kind == "egocentric":
        if len(paths) != 1:
            raise InvalidInput(f"the ego-centric format is one CSV or Parquet file, got "
                               f"{len(paths)} files", field="body.files")
        target: Path = paths[0]
    else:
        folder = {p.parent for p in paths}
        if len(folder) != 1:
            raise InvalidInput("highD files must be uploaded together", field="body.files")
        target = folder.pop()
    try:
        result = extract(target, kind)
    except NotImplementedError as exc:
        raise DomainUnavailable(f"reading {kind} files: {exc}") from None
    except (ValueError, OSError, KeyError) as exc:
        # a malformed upload (pyarrow and pandas raise their own ValueError/OSError kinds)
        raise InvalidInput(f"{kind} upload: {exc}", field="body.files") from None
    skipped = [{"event_id": e, "reason": r} for e, r in result.skipped]
    report = {"n_cutins": len(result.table), "n_skipped": len(skipped),
              "skipped": skipped[:200], "files": [p.name for p in paths]}
    return result.table, report


# --------------------------------------------------------------------------- models
@dataclass(frozen=True)
class FittedModel:
    model: Any
    model_json: str
    model_hash: str
    n_components: int
    bic_curve: list[dict[str, Any]]
    fit_report: dict[str, Any]


def fit_model(table: pd.DataFrame, options: Mapping[str, Any],
              source: str | None = None) -> FittedModel:
    """Fit the cut-in GMM on a parameter table with the sampler's options."""
    cls = _need("sampler.model", "CutInGMM")
    kwargs = dict(options)
    if isinstance(kwargs.get("k_range"), list):
        kwargs["k_range"] = tuple(kwargs["k_range"])
    try:
        model = cls(**kwargs)
    except TypeError as exc:
        raise InvalidInput(f"model options: {exc}", field="body.options") from None
    try:
        model.fit(table, source=source)
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
    """Weight, mean and covariance of each mixture component, in the model's z-space
    (each feature transformed and standardised; see the model's ``transforms``)."""
    weights = np.asarray(getattr(model, "weights_", []), dtype=float)
    means = np.asarray(getattr(model, "means_", []), dtype=float)
    covs = np.asarray(getattr(model, "covariances_", []), dtype=float)
    names = [str(n) for n in getattr(model, "features_", PARAM_NAMES)]
    out = []
    for k in range(len(weights)):
        out.append({
            "weight": float(weights[k]),
            "mean_z": {n: float(m) for n, m in zip(names, means[k], strict=False)},
            "covariance_z": jsonable(covs[k]) if covs.size else None,
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
            # the sampler's message already quotes the constraint; do not repeat it
            msg = str(exc)
            if repr(text) not in msg:
                msg = f"constraint {text!r}: {msg}"
            raise InvalidInput(msg, field=f"{field}.{i}") from None
    return out


@dataclass(frozen=True)
class SampleResult:
    """What the service keeps of a sampler SampleSet."""

    params: pd.DataFrame  # columns PARAM_NAMES, one row per sample
    weights: np.ndarray  # exposure weight per sample
    p_region: dict[str, Any]  # {"estimate", "ci": [lo, hi], ...}
    diagnostics: dict[str, Any]
    lane_width: float  # m, the region's lane width: build the scenarios with it


def _region_dict(pr: Any) -> dict[str, Any]:
    """A PRegion as JSON: its fields plus ``ci`` = [ci_low, ci_high]."""
    out = dict(pr.to_dict())
    out["ci"] = [out.get("ci_low"), out.get("ci_high")]
    return out


def _sampler_call(fn: Any, *args: Any, **kwargs: Any) -> Any:
    empty = _need("sampler", "EmptyRegionError")
    try:
        return fn(*args, **kwargs)
    except empty as exc:
        raise InvalidInput(f"the region is (practically) empty: {exc}",
                           field="body.constraints") from None
    except ValueError as exc:
        raise InvalidInput(f"sampling failed: {exc}", field="body") from None


def sample(model: Any, constraints: Sequence[Any], n: int, seed: int,
           method: str = "auto") -> SampleResult:
    """``n`` samples of ``model`` in the region (``sampler.sample``)."""
    fn = _need("sampler.sampleset", "sample")
    ss = _sampler_call(fn, model, list(constraints), n, seed, method)
    diagnostics = dict(ss.diagnostics)
    diagnostics["method"] = ss.method
    diagnostics["requested_method"] = ss.requested
    return SampleResult(
        params=ss.params,
        weights=np.asarray(ss.exposure_weights, dtype=np.float64),
        p_region=_region_dict(ss.p_region),
        diagnostics=diagnostics,
        lane_width=float(ss.region.lane_width),
    )


def estimate_region(model: Any, constraints: Sequence[Any], seed: int) -> dict[str, Any]:
    """P(A) of the constraint region under the model: ``{"estimate", "ci": [lo, hi], ...}``."""
    fn = _need("sampler.sampleset", "estimate_p_region")
    return _region_dict(_sampler_call(fn, model, list(constraints), seed))


def ttc_of(params: Mapping[str, float]) -> float:
    return float(ttc_from_gap_dv(params["gap"], params["dv"]))


# --------------------------------------------------------------------------- scenarios
def model_lane_width(model: Any) -> float:
    """The lane width (m) the model's region and scenarios use."""
    return float(model.lane_width_)


def build_scenario(params: Mapping[str, float], seed: int, lane_width: float | None = None,
                   provenance: Mapping[str, Any] | None = None) -> ConcreteScenario:
    """The concrete scenario of one parameter vector (``sampler.build_scenario``) on a road
    with lanes ``lane_width`` m wide. Pass the sample set's lane width (its region's crossing
    test used it; ``SampleResult.lane_width`` or ``model_lane_width``); None = the builder's
    default, which may refuse vectors sampled for a narrower lane."""
    fn = _need("sampler.builder", "build_scenario")
    kwargs: dict[str, Any] = {"seed": seed, "provenance": provenance}
    if lane_width is not None:
        kwargs["lane_width"] = lane_width
    try:
        result: ConcreteScenario = fn(dict(params), **kwargs)
    except ValueError as exc:
        raise InvalidInput(f"building the scenario failed: {exc}", field="params") from None
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
    try:
        risk = fn(scenario)
    except ValueError as exc:  # riskcore's errors name the field (e.g. "ego.v[3]: ...")
        raise InvalidInput(str(exc), field=_scenario_field(str(exc))) from None
    return {"summary": jsonable(dict(risk.summary())), "risk": jsonable(risk.to_dict())}


def _scenario_field(message: str) -> str:
    head = message.split(":", 1)[0].strip()
    if not head or " " in head or head == "scenario":
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
