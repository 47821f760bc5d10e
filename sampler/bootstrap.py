"""Model uncertainty: bootstrap refits of the mixture and the "model" interval of P(A).

The GMM was fitted to a few hundred events; in the tails, where rare regions lie, that fit
is the dominant uncertainty (de Gelder et al., IEEE Access 2021, include 1,000 bootstrap
refits of their data model in their interval). Here:

* ``bootstrap_fit(model, table, n_boot, seed, n_jobs)``: ``n_boot`` nonparametric
  bootstrap replicates of the training rows (resampled with replacement), each refitted
  with the model's K, covariance type, transforms and regularisation by one EM run started
  from the fitted mixture (sklearn ``GaussianMixture`` with ``weights_init``/``means_init``/
  ``precisions_init``, ``n_init = 1``). The cheap options are deliberate: K is not chosen
  again by BIC and the transforms' standardisation is kept (the uncertainty of the choice
  of K is not in the interval). Replicate b uses its own seed spawned from ``seed`` (numpy
  ``SeedSequence``), so the result does not depend on ``n_jobs``. Run on a local process
  pool (``concurrent.futures``) when ``n_jobs > 1`` (0: one per core). Cost measured on the
  TNO model (K = 3, 208 rows): 11 ms per replicate single-threaded, so B = 100 takes about
  1 s in one process and the default is ``n_jobs = 1`` (with multi-threaded BLAS on the
  loaded 2-core machine it was 0.3 s per replicate: the refits run single-threaded). The
  replicates are stored with the model (``model.bootstrap_``, saved in its JSON), so no
  request refits.
* ``model_interval(model, z_inside, p_joint, ...)``: P(A) under each replicate by importance
  reweighting of samples of the fitted model restricted to A,
  ``P_b(A and B) = P(A and B) mean_i p_b(x_i) / p(x_i)`` (all replicates share the
  transforms, so the ratio is the same in z-space and in original units), ``P_b(B)`` the
  same from plain draws of the model; the "model" interval is the replicates' percentile
  interval of ``P_b(A and B) / P_b(B)``. No refit and no new limit-state evaluation, so it
  costs B density evaluations of the sample set.
"""
from __future__ import annotations

import math
import os
import warnings
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from sampler._exceptions import ModelError
from sampler._threads import single_threaded

__all__ = ["bootstrap_fit", "log_density_z_boot", "model_interval"]

FloatArray = NDArray[np.float64]


@single_threaded
def _refit(args: tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, int, list[int]]
           ) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
    """Refit one chunk of replicates (runs in a worker process)."""
    from sklearn.mixture import GaussianMixture

    z, weights, means, covs, reg, max_iter, seeds = args
    n = z.shape[0]
    k = weights.shape[0]
    precisions = np.stack([np.linalg.inv(c) for c in covs])
    out = []
    for s in seeds:
        rng = np.random.default_rng(s)
        zb = z[rng.integers(0, n, size=n)]
        gm = GaussianMixture(n_components=k, covariance_type="full", reg_covar=reg,
                             max_iter=max_iter, n_init=1, weights_init=weights,
                             means_init=means, precisions_init=precisions,
                             random_state=int(rng.integers(0, 2**31 - 1)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a ConvergenceWarning: the replicate is kept
            gm.fit(zb)
        out.append((np.asarray(gm.weights_, dtype=np.float64),
                    np.asarray(gm.means_, dtype=np.float64),
                    np.asarray(gm.covariances_, dtype=np.float64)))
    return out


def bootstrap_fit(model: Any, table: Any, n_boot: int = 100, seed: int = 0,
                  n_jobs: int = 1) -> dict[str, Any]:
    """Bootstrap refits of a fitted ``CutInGMM`` on its training table; sets and returns
    ``model.bootstrap_`` (JSON-able: ``n_boot``, ``seed``, ``method``, ``weights``,
    ``means``, ``covariances`` per replicate, z-space)."""
    model._check_fitted()
    n_boot = int(n_boot)
    if not 2 <= n_boot <= 10_000:
        raise ModelError(f"n_bootstrap: expected 2 ... 10000 replicates, got {n_boot}")
    if model.covariance_type != "full":
        raise ModelError("bootstrap: only covariance_type='full' models are supported")
    x = model._table_matrix(table, model.features_)
    z = model._forward(x)[0]
    if not np.isfinite(z).all():
        raise ModelError("bootstrap: the table has rows outside the model's transforms")
    children = np.random.SeedSequence(int(seed)).spawn(n_boot)
    seeds = [int(c.generate_state(1)[0]) for c in children]
    jobs = max(1, min(int(n_jobs) if n_jobs > 0 else (os.cpu_count() or 1), n_boot))
    base = (z, model.weights_, model.means_, model.covariances_, float(model.reg_covar),
            int(model.max_iter))
    chunks = [seeds[i::jobs] for i in range(jobs)]
    if jobs == 1:
        parts = [_refit((*base, chunks[0]))]
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            parts = list(pool.map(_refit, [(*base, c) for c in chunks]))
    # undo the round-robin chunking: replicate i is parts[i % jobs][i // jobs]
    reps = [parts[i % jobs][i // jobs] for i in range(n_boot)]
    model.bootstrap_ = {
        "n_boot": n_boot, "seed": int(seed), "n_rows": int(z.shape[0]),
        "method": "nonparametric row resampling; K, transforms and reg_covar fixed; one EM "
                  "run from the fitted mixture",
        "weights": [r[0].tolist() for r in reps],
        "means": [r[1].tolist() for r in reps],
        "covariances": [r[2].tolist() for r in reps],
    }
    return model.bootstrap_


def _mixture_logpdf(z: FloatArray, weights: FloatArray, means: FloatArray,
                    covs: FloatArray) -> FloatArray:
    k, d = means.shape
    comp = np.empty((k, z.shape[0]))
    for j in range(k):
        chol = np.linalg.cholesky(covs[j])
        y = np.linalg.solve(chol, (z - means[j]).T)
        comp[j] = (math.log(weights[j]) if weights[j] > 0 else -np.inf) \
            - 0.5 * d * math.log(2 * math.pi) - np.log(np.diag(chol)).sum() \
            - 0.5 * np.einsum("ij,ij->j", y, y)
    return np.asarray(logsumexp(comp, axis=0), dtype=np.float64)


def log_density_z_boot(model: Any, z: FloatArray) -> FloatArray:
    """Log-densities (B, n) of rows z (n, d) under each stored bootstrap replicate."""
    boot = getattr(model, "bootstrap_", None)
    if not boot:
        raise ModelError("this model has no bootstrap replicates: fit with n_bootstrap > 0")
    return np.stack([_mixture_logpdf(z, np.asarray(w), np.asarray(m), np.asarray(c))
                     for w, m, c in zip(boot["weights"], boot["means"], boot["covariances"],
                                        strict=True)])


def model_interval(model: Any, z_inside: FloatArray, p_joint: float, z_plain: FloatArray,
                   in_bounds: NDArray[np.bool_], confidence: float = 0.95
                   ) -> dict[str, Any]:
    """The "model" interval of P(A) = P(A and B) / P(B) from the bootstrap replicates.

    Parameters
    ----------
    z_inside : (n, d) samples of the fitted model restricted to A (A inside B)
    p_joint : P(A and B) under the fitted model
    z_plain : (m, d) plain draws of the fitted model; ``in_bounds`` marks those in B
    """
    lp = model.log_density_z(z_inside)
    ratio = np.exp(log_density_z_boot(model, z_inside) - lp)        # (B, n)
    joint_b = p_joint * ratio.mean(axis=1)
    lq = model.log_density_z(z_plain)
    w_plain = np.exp(log_density_z_boot(model, z_plain) - lq)        # (B, m)
    pb_b = (w_plain * in_bounds).mean(axis=1)
    p_b = np.where(pb_b > 0, joint_b / np.where(pb_b > 0, pb_b, 1.0), np.nan)
    p_b = np.minimum(p_b, 1.0)
    alpha = 1.0 - confidence
    ok = p_b[np.isfinite(p_b)]
    lo, hi = (np.quantile(ok, [alpha / 2, 1 - alpha / 2]) if ok.size
              else (math.nan, math.nan))
    return {"ci": [float(lo), float(hi)], "confidence": confidence,
            "median": float(np.median(ok)) if ok.size else math.nan,
            "n_boot": int(p_b.size), "cov": float(np.std(ok) / np.mean(ok))
            if ok.size and np.mean(ok) > 0 else math.nan,
            "replicates": [float(v) for v in p_b],
            "method": "bootstrap refits, importance reweighting of the sample set"}
