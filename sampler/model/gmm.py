"""The logical-scenario model: a Gaussian mixture over transformed cut-in parameters.

``CutInGMM`` is a scikit-learn style estimator: ``__init__`` stores settings, ``fit``
validates the parameter table and sets the learned attributes (ending in ``_``). The
mixture lives in the standardised transformed space ``z`` (see ``sampler.model.transforms``);
``log_density`` returns the density in *original units* (Jacobian included).

The number of components K is chosen by BIC over ``k_range`` (the whole curve is kept in
``bic_curve_``), each K fitted with ``n_init`` seeded restarts. BIC here is computed in
original units, ``-2 sum log p(x_i) + n_par log n`` with
``n_par = K - 1 + K d + K d (d + 1) / 2`` for full covariances (the Jacobian term is the
same for every K, so the choice equals sklearn's ``bic`` in z-space).

Parameters the model does not include (when ``features`` is a subset of ``PARAM_NAMES``)
are held at fixed values (``fixed_``: the table's median unless given), so sampling always
yields full parameter vectors.

Persistence is JSON only (``to_json``/``from_json``, ``save``/``load``; the format is in
``sampler.model.io``); the fit report and its text are in ``sampler.model.fit_report``.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import sklearn
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import solve_triangular
from scipy.special import logsumexp
from sklearn.mixture import GaussianMixture

from datasets import DEFAULT_LANE_WIDTH, PARAM_NAMES
from sampler._threads import single_threaded
from sampler.errors import ModelError, NotFittedError
from sampler.intervals import clopper_pearson
from sampler.model import memo
from sampler.model.fit_report import fit_report, report_text
from sampler.model.io import FORMAT, model_from_dict, model_to_dict
from sampler.model.support import (
    SupportMeasures,
    density_percentile,
    support_dict,
    support_measures,
)
from sampler.model.transforms import FeatureTransform, transform_spec

__all__ = ["FORMAT", "CutInGMM", "clopper_pearson"]

FloatArray = NDArray[np.float64]
_LOG_2PI = math.log(2.0 * math.pi)
_COV_TYPES = ("full", "tied", "diag", "spherical")


def _full_covariances(gm: GaussianMixture, d: int) -> FloatArray:
    k = gm.n_components
    cov = np.asarray(gm.covariances_, dtype=np.float64)
    if gm.covariance_type == "full":
        return cov.copy()
    if gm.covariance_type == "tied":
        return np.repeat(cov[None, :, :], k, axis=0)
    if gm.covariance_type == "diag":
        return np.stack([np.diag(c) for c in cov])
    return np.stack([np.eye(d) * c for c in cov])  # spherical


def _n_parameters(k: int, d: int, covariance_type: str) -> int:
    cov = {"full": k * d * (d + 1) // 2, "tied": d * (d + 1) // 2, "diag": k * d,
           "spherical": k}[covariance_type]
    return k - 1 + k * d + cov


class CutInGMM:
    """Gaussian mixture over (transformed) cut-in parameters, K chosen by BIC.

    Parameters
    ----------
    features : sequence of str, optional
        Table columns modelled, default ``PARAM_NAMES``.
    transforms : mapping of feature -> spec, optional
        Per-feature transform overrides (``"identity"``, ``"log"``,
        ``("log_shift", shift)``); the rest use ``DEFAULT_TRANSFORMS``.
    k_range : (int, int)
        Smallest and largest number of components tried (inclusive).
    n_init : int
        EM restarts per K (sklearn's ``n_init``); the best is kept.
    covariance_type : {"full", "tied", "diag", "spherical"}
    reg_covar : float
        Added to the covariance diagonals in z-space (z is standardised).
    max_iter : int
        EM iterations per restart.
    random_state : int
        Seed of the restarts, the cross-validation split and the report's model samples.
    cv_folds : int
        Folds of the held-out log-likelihood in the fit report.
    n_report_samples : int
        Model draws for the report's KS statistics and out-of-bounds mass.
    lane_width : float, optional
        Lane width in m of the data (crossing = half of it from the start-lane centre); the
        default for sampling regions and the builder. None: the median of the table's
        ``lane_width`` column when it has one, else ``DEFAULT_LANE_WIDTH``.
    fixed : mapping of str -> float, optional
        Values for parameters not in ``features`` (default: the table's medians).

    Attributes
    ----------
    features_ : tuple of str
    transforms_ : tuple of FeatureTransform
    weights_ : ndarray of shape (K,)
    means_ : ndarray of shape (K, d)          z-space
    covariances_ : ndarray of shape (K, d, d) z-space, full matrices
    n_components_ : int
    cholesky_ : ndarray of shape (K, d, d)     lower Cholesky factors of the covariances
    cholesky_inv_ : ndarray of shape (K, d, d) their inverses
    log_norm_ : ndarray of shape (K,)          log normalising constant of each component
    weights_cdf_ : ndarray of shape (K,)       cumulative weights (last exactly 1): drawing
                                               a component is a ``searchsorted`` on it
    bic_curve_ : list of dict (k, bic, log_likelihood, n_parameters, converged, error)
    fit_report_ : dict (see ``fit``)
    fixed_ : dict of str -> float
    lane_width_ : float
    training_ : dict (n_rows, sha256, source)
    sklearn_version_ : str
    """

    #: data exposure (``sampler.rates.exposure.Exposure.to_dict``), bootstrap replicates
    #: (``sampler.model.bootstrap``) and the tail calibration report; None until set
    exposure_: dict[str, Any] | None = None
    bootstrap_: dict[str, Any] | None = None
    tail_calibration_: dict[str, Any] | None = None
    #: the training rows and the data-support rule (``sampler.model.support``); None for a
    #: model file written before data support
    support_: dict[str, Any] | None = None

    def __init__(
        self,
        features: Sequence[str] | None = None,
        transforms: Mapping[str, Any] | None = None,
        *,
        k_range: tuple[int, int] = (1, 8),
        n_init: int = 5,
        covariance_type: str = "full",
        reg_covar: float = 1e-4,
        max_iter: int = 500,
        random_state: int = 0,
        cv_folds: int = 5,
        n_report_samples: int = 20_000,
        lane_width: float | None = None,
        fixed: Mapping[str, float] | None = None,
    ) -> None:
        self.features = features
        self.transforms = transforms
        self.k_range = k_range
        self.n_init = n_init
        self.covariance_type = covariance_type
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.random_state = random_state
        self.cv_folds = cv_folds
        self.n_report_samples = n_report_samples
        self.lane_width = lane_width
        self.fixed = fixed

    # ------------------------------------------------------------------ validation

    def _check_settings(self) -> tuple[tuple[str, ...], int, int]:
        features = tuple(PARAM_NAMES if self.features is None else self.features)
        if not features or len(set(features)) != len(features):
            raise ModelError(f"features: need distinct names, got {features!r}")
        try:
            k_lo, k_hi = (int(k) for k in self.k_range)
        except (TypeError, ValueError):
            raise ModelError(f"k_range: expected (min, max), got {self.k_range!r}") from None
        if not 1 <= k_lo <= k_hi:
            raise ModelError(f"k_range: need 1 <= min <= max, got {self.k_range!r}")
        if self.covariance_type not in _COV_TYPES:
            raise ModelError(f"covariance_type: {self.covariance_type!r} is not one of "
                             f"{', '.join(_COV_TYPES)}")
        if int(self.n_init) < 1 or int(self.max_iter) < 1 or int(self.cv_folds) < 2:
            raise ModelError("n_init, max_iter must be >= 1 and cv_folds >= 2")
        if not (self.reg_covar >= 0 and math.isfinite(self.reg_covar)):
            raise ModelError(f"reg_covar: must be >= 0, got {self.reg_covar!r}")
        if self.lane_width is not None and not (0 < self.lane_width <= 10):
            raise ModelError(f"lane_width: must be in (0, 10] m, got {self.lane_width!r}")
        return features, k_lo, k_hi

    @staticmethod
    def table_matrix(table: Any, features: Sequence[str], where: str = "table") -> FloatArray:
        if isinstance(table, Mapping):
            table = pd.DataFrame(dict(table))
        if not isinstance(table, pd.DataFrame):
            raise ModelError(f"{where}: expected a pandas DataFrame, got {type(table).__name__}")
        missing = [f for f in features if f not in table.columns]
        if missing:
            raise ModelError(f"{where}: missing column(s) {', '.join(missing)}; "
                             f"has {', '.join(map(str, table.columns))}")
        cols = []
        for f in features:
            try:
                col = pd.to_numeric(table[f], errors="raise").to_numpy(dtype=np.float64)
            except (TypeError, ValueError):
                raise ModelError(f"{where}: column {f!r} is not numeric") from None
            bad = np.flatnonzero(~np.isfinite(col))
            if bad.size:
                raise ModelError(f"{where}: column {f!r} row {int(bad[0])} is not a finite "
                                 f"number ({col[bad[0]]!r}); {bad.size} such row(s)")
            cols.append(col)
        return np.column_stack(cols)

    # ------------------------------------------------------------------ fitting

    @single_threaded
    def fit(self, table: pd.DataFrame, *, source: str | None = None) -> CutInGMM:
        """Fit to a parameter table (one row per cut-in, columns ``features``).

        Sets ``bic_curve_``, ``n_components_`` and ``fit_report_`` =
        ``{"n_rows", "k", "bic", "loglik_per_row" (in sample, original units),
        "heldout_loglik_per_row": {"mean", "std", "folds", "per_fold"} (K-fold CV, chosen K),
        "ks": {feature: {"statistic", "pvalue"}} (data vs ``n_report_samples`` model draws),
        "outside_bounds": {"fraction", "ci95", "per_bound", "lane_width", "n_samples"}}``.

        Raises
        ------
        ModelError
            Missing/non-numeric/non-finite columns (naming column and row), values outside a
            transform's domain, too few rows, or every K failing to fit.
        """
        features, k_lo, k_hi = self._check_settings()
        memo.clear(self)  # P(B) and model intervals of an earlier fit
        x = self.table_matrix(table, features)
        n, d = x.shape
        if n < max(2 * d, 10):
            raise ModelError(f"table: {n} rows are too few to fit {d} features "
                             f"(need at least {max(2 * d, 10)})")
        transforms = self._fit_transforms(x, features)
        self.features_ = features
        self.transforms_ = tuple(transforms)
        self.fixed_ = self._fixed_values(table, features)
        self.lane_width_ = self._lane_width(table)
        z, logj = self._forward(x)
        sum_logj = float(logj.sum())

        k_hi = min(k_hi, n - 1)
        if k_hi < k_lo:
            raise ModelError(f"k_range: {self.k_range} needs more than {n} rows")
        curve, best = self._bic_curve(z, sum_logj, range(k_lo, k_hi + 1))
        if best is None:
            raise ModelError("fit: every number of components failed: "
                             + "; ".join(f"K={c['k']}: {c['error']}" for c in curve))
        gm = best[1]
        self.set_mixture(np.asarray(gm.weights_, dtype=np.float64),
                          np.asarray(gm.means_, dtype=np.float64),
                          _full_covariances(gm, d))
        self.bic_curve_ = curve
        self.training_ = {"n_rows": n, "sha256": self._hash(x, features), "source": source}
        self.support_ = support_dict(x, features)
        self.sklearn_version_ = sklearn.__version__
        self.fit_report_ = self._report(x, z, logj, best[0])
        return self

    def _fit_transforms(self, x: FloatArray, features: tuple[str, ...]
                        ) -> list[FeatureTransform]:
        """Each feature's transform (``transforms``, else the feature's default), centred
        and scaled to the table's values ``x`` in transformed space. ModelError: a
        transform for a feature the model does not have, a value outside a transform's
        domain, a constant column."""
        specs = {f: transform_spec(f, (self.transforms or {}).get(f)) for f in features}
        unknown_t = sorted(set(self.transforms or {}) - set(features))
        if unknown_t:
            raise ModelError(f"transforms: not model features: {', '.join(unknown_t)}")
        transforms = []
        for j, f in enumerate(features):
            kind, shift = specs[f]
            probe = FeatureTransform(f, kind, shift, 0.0, 1.0)
            bad = np.flatnonzero(~probe.in_domain(x[:, j]))
            if bad.size:
                raise ModelError(
                    f"table: column {f!r} row {int(bad[0])} = {x[bad[0], j]!r} is outside the "
                    f"{kind} transform's domain ({probe.domain_text()}); choose another "
                    f"transform for {f!r}"
                )
            y = probe.g(x[:, j])
            scale = float(np.std(y))
            if not scale > 0:
                raise ModelError(f"table: column {f!r} is constant; drop it from features "
                                 "and give it as a fixed value")
            transforms.append(FeatureTransform(f, kind, shift, float(np.mean(y)), scale))
        return transforms

    def _bic_curve(self, z: FloatArray, sum_logj: float, ks: range
                   ) -> tuple[list[dict[str, Any]], tuple[float, GaussianMixture] | None]:
        """A mixture of each number of components in ``ks`` fitted to the transformed
        rows ``z``: the BIC curve (in original units: ``sum_logj``, the transforms' log
        Jacobian) and the (BIC, mixture) of the lowest BIC (None: every K failed)."""
        n, d = z.shape
        curve: list[dict[str, Any]] = []
        best: tuple[float, GaussianMixture] | None = None
        for k in ks:
            gm, converged, err = self._fit_gm(k, z)
            entry: dict[str, Any] = {"k": k, "n_parameters": _n_parameters(k, d,
                                                                           self.covariance_type)}
            if gm is None:
                entry.update(bic=None, log_likelihood=None, converged=False, error=err)
            else:
                ll = float(gm.score(z)) * n + sum_logj
                bic = -2.0 * ll + entry["n_parameters"] * math.log(n)
                entry.update(bic=bic, log_likelihood=ll, converged=converged, error=None)
                if best is None or bic < best[0]:
                    best = (bic, gm)
            curve.append(entry)
        return curve, best

    def _fit_gm(self, k: int, z: FloatArray) -> tuple[GaussianMixture | None, bool, str | None]:
        gm = GaussianMixture(n_components=k, covariance_type=self.covariance_type,
                             n_init=int(self.n_init), reg_covar=float(self.reg_covar),
                             max_iter=int(self.max_iter), random_state=int(self.random_state))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                gm.fit(z)
            except (ValueError, np.linalg.LinAlgError) as exc:
                return None, False, str(exc).splitlines()[0]
        not_conv = any("converge" in str(w.message).lower() for w in caught)
        return gm, bool(gm.converged_) and not not_conv, None

    def _fixed_values(self, table: Any, features: Sequence[str]) -> dict[str, float]:
        fixed: dict[str, float] = {}
        given = dict(self.fixed or {})
        for name in PARAM_NAMES:
            if name in features:
                continue
            if name in given:
                fixed[name] = float(given[name])
            elif isinstance(table, pd.DataFrame) and name in table.columns:
                fixed[name] = float(np.median(self.table_matrix(table, [name])[:, 0]))
            else:
                raise ModelError(f"fixed: parameter {name!r} is neither a feature nor in the "
                                 "table; give it in fixed={...}")
            if not math.isfinite(fixed[name]):
                raise ModelError(f"fixed.{name}: must be finite")
        return fixed

    def _lane_width(self, table: Any) -> float:
        if self.lane_width is not None:
            return float(self.lane_width)
        if isinstance(table, pd.DataFrame) and "lane_width" in table.columns:
            w = pd.to_numeric(table["lane_width"], errors="coerce").to_numpy(dtype=np.float64)
            w = w[np.isfinite(w) & (w > 0)]
            if w.size:
                return float(np.median(w))
        return float(DEFAULT_LANE_WIDTH)

    @staticmethod
    def _hash(x: FloatArray, features: Sequence[str]) -> str:
        h = hashlib.sha256(json.dumps(list(features)).encode())
        h.update(np.ascontiguousarray(x, dtype="<f8").tobytes())
        return h.hexdigest()

    def set_mixture(self, weights: FloatArray, means: FloatArray, covs: FloatArray) -> None:
        """Set the z-space mixture (weights (K,), means (K, d), covariances (K, d, d)) and
        everything derived from it; checks shapes, finiteness and positive definiteness.
        For refits and replicates (``sampler.model.bootstrap``) and persistence."""
        k, d = means.shape
        if weights.shape != (k,) or covs.shape != (k, d, d):
            raise ModelError(f"mixture: inconsistent shapes weights {weights.shape}, "
                             f"means {means.shape}, covariances {covs.shape}")
        if not (np.isfinite(weights).all() and np.isfinite(means).all()
                and np.isfinite(covs).all()):
            raise ModelError("mixture: weights, means and covariances must be finite")
        if (weights < 0).any() or abs(weights.sum() - 1.0) > 1e-9:
            raise ModelError(f"mixture: weights must be >= 0 and sum to 1, got {weights.sum()}")
        chol = np.empty_like(covs)
        for i in range(k):
            if not np.allclose(covs[i], covs[i].T, rtol=0, atol=1e-12):
                raise ModelError(f"mixture: covariance {i} is not symmetric")
            try:
                chol[i] = np.linalg.cholesky(covs[i])
            except np.linalg.LinAlgError:
                raise ModelError(f"mixture: covariance {i} is not positive definite") from None
        self.weights_ = weights
        self.means_ = means
        self.covariances_ = covs
        self.cholesky_ = chol
        # inverse factors: the Mahalanobis term is one small matmul per component
        self.cholesky_inv_ = np.stack([solve_triangular(c, np.eye(d), lower=True) for c in chol])
        self._log_weights = np.log(np.where(weights > 0, weights, 1.0))
        self._log_weights[weights == 0] = -np.inf
        self.log_norm_ = -0.5 * d * _LOG_2PI - np.log(np.diagonal(chol, axis1=1,
                                                                  axis2=2)).sum(axis=1)
        self.weights_cdf_ = np.cumsum(weights)
        self.weights_cdf_[-1] = 1.0
        self.n_components_ = k

    # ------------------------------------------------------------------ densities

    def check_fitted(self) -> None:
        """Raise :class:`NotFittedError` unless the model is fitted (or loaded)."""
        if not hasattr(self, "weights_"):
            raise NotFittedError("this CutInGMM is not fitted: call fit(table) or load a model")

    @property
    def n_features(self) -> int:
        self.check_fitted()
        return len(self.features_)

    def _forward(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        z = np.empty_like(x)
        logj = np.zeros(x.shape[0])
        for j, tr in enumerate(self.transforms_):
            z[:, j], lj = tr.forward(x[:, j])
            logj += lj
        return z, logj

    def to_z(self, x: ArrayLike) -> FloatArray:
        """Original units (n, d) -> z-space (n, d); NaN outside a transform's domain."""
        self.check_fitted()
        return self._forward(self._as_x(x))[0]

    def from_z(self, z: ArrayLike) -> FloatArray:
        """z-space (n, d) -> original units (n, d)."""
        self.check_fitted()
        z_a = np.atleast_2d(np.asarray(z, dtype=np.float64))
        return np.column_stack([tr.inverse(z_a[:, j]) for j, tr in enumerate(self.transforms_)])

    def _as_x(self, x: ArrayLike | pd.DataFrame) -> FloatArray:
        if isinstance(x, pd.DataFrame):
            missing = [f for f in self.features_ if f not in x.columns]
            if missing:
                raise ModelError(f"X: missing column(s) {', '.join(missing)}")
            return x[list(self.features_)].to_numpy(dtype=np.float64)
        arr = np.atleast_2d(np.asarray(x, dtype=np.float64))
        if arr.ndim != 2 or arr.shape[1] != len(self.features_):
            raise ModelError(f"X: expected shape (n, {len(self.features_)}) with columns "
                             f"{self.features_}, got {arr.shape}")
        return arr

    def log_density_z(self, z: ArrayLike) -> FloatArray:
        """Log-density of the mixture in z-space, shape (n,); NaN rows give -inf."""
        self.check_fitted()
        z_a = np.atleast_2d(np.asarray(z, dtype=np.float64))
        n = z_a.shape[0]
        ok = np.isfinite(z_a).all(axis=1)
        out = np.full(n, -np.inf)
        if not ok.any():
            return out
        zz = z_a[ok]
        comp = np.empty((self.n_components_, zz.shape[0]))
        for k in range(self.n_components_):
            y = (zz - self.means_[k]) @ self.cholesky_inv_[k].T
            comp[k] = self._log_weights[k] + self.log_norm_[k] - 0.5 * np.einsum("ij,ij->i", y, y)
        out[ok] = logsumexp(comp, axis=0)
        return out

    def log_density(self, x: ArrayLike | pd.DataFrame) -> FloatArray:
        """Log-density in original units (Jacobian included), shape (n,).

        ``X`` has shape (n, d) with columns ``features_`` (or is a DataFrame with them).
        Rows outside a transform's domain (e.g. gap <= 0 with a log transform) give -inf.
        """
        self.check_fitted()
        z, logj = self._forward(self._as_x(x))
        with np.errstate(invalid="ignore"):
            out = self.log_density_z(z) + logj
        return np.where(np.isfinite(logj), out, -np.inf)

    def score(self, x: ArrayLike | pd.DataFrame) -> float:
        """Mean log-density per row in original units."""
        return float(np.mean(self.log_density(x)))

    # ------------------------------------------------------------------ sampling

    def sample_z(self, n: int, rng: np.random.Generator, scale: float = 1.0) -> FloatArray:
        """``n`` draws in z-space, shape (n, d), from the Generator ``rng`` (advanced).

        Component labels are drawn first (inverse CDF of uniforms), then one standard
        normal vector per row, so rows are i.i.d. and not grouped by component. ``scale``
        > 1 widens every component (covariances times ``scale**2``): the broadened search
        for rare regions uses it.
        """
        self.check_fitted()
        if not isinstance(rng, np.random.Generator):
            raise TypeError("rng: expected a numpy Generator (np.random.default_rng(seed))")
        n = int(n)
        labels = np.searchsorted(self.weights_cdf_, rng.random(n), side="right")
        np.minimum(labels, self.n_components_ - 1, out=labels)
        e = rng.standard_normal((n, self.n_features))
        z = np.empty_like(e)
        for k in range(self.n_components_):
            idx = labels == k
            z[idx] = self.means_[k] + (e[idx] @ self.cholesky_[k].T) * scale
        return z

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` draws in original units, shape (n, d), columns ``features_``."""
        return self.from_z(self.sample_z(n, rng))

    def density_percentile(self, params: ArrayLike) -> FloatArray:
        """``density_pct`` of full parameter vectors (n, 8) in ``PARAM_NAMES`` order: the
        share of the model's physical cut-ins less probable than each
        (:mod:`sampler.model.support`)."""
        return density_percentile(self, np.asarray(params, dtype=np.float64))

    def support_measures(self, params: ArrayLike, *, with_density: bool = False
                         ) -> SupportMeasures:
        """How far full parameter vectors (n, 8) in ``PARAM_NAMES`` order lie from the
        training data: per parameter, nearest real cut-in, class
        (:mod:`sampler.model.support`)."""
        return support_measures(self, np.asarray(params, dtype=np.float64),
                                with_density=with_density)

    def params_matrix(self, x: ArrayLike) -> FloatArray:
        """Full parameter vectors (n, 8) in ``PARAM_NAMES`` order from model features (n, d).

        Parameters that are not features take their ``fixed_`` value.
        """
        self.check_fitted()
        x_a = np.atleast_2d(np.asarray(x, dtype=np.float64))
        out = np.empty((x_a.shape[0], len(PARAM_NAMES)))
        for i, name in enumerate(PARAM_NAMES):
            if name in self.features_:
                out[:, i] = x_a[:, self.features_.index(name)]
            else:
                out[:, i] = self.fixed_[name]
        return out

    # ------------------------------------------------------------------ report

    def _report(self, x: FloatArray, z: FloatArray, logj: FloatArray,
                bic: float) -> dict[str, Any]:
        return fit_report(self, x, z, logj, bic)

    def report_text(self) -> str:
        """Human-readable BIC curve and fit report (what ``scengen fit`` prints)."""
        return report_text(self)

    # ------------------------------------------------------------------ persistence

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (plain lists and numbers); see ``sampler.model.io``."""
        return model_to_dict(self)

    def to_json(self, indent: int | None = None) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, data: Any) -> CutInGMM:
        """Rebuild from ``to_dict``'s form. Raises ModelError naming the bad field."""
        return model_from_dict(cls, data)

    @classmethod
    def from_json(cls, text: str) -> CutInGMM:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelError(f"model: not valid JSON ({exc})") from None
        return cls.from_dict(data)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json(indent=1) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, path: str | Path) -> CutInGMM:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as exc:
            raise ModelError(f"{path}: cannot read model ({exc.strerror or exc})") from None
        try:
            return cls.from_json(text)
        except ModelError as exc:
            raise ModelError(f"{path}: {exc}") from None
