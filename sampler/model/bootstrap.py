"""Model uncertainty: bootstrap refits of the mixture (the "model" interval of P(A) built on
them is :mod:`sampler.rates.bootstrap_interval`).

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
* Why not reweight the fitted model's own samples of A
  (``P_b(A) = P(A) mean_i p_b(x_i) / p(x_i)``, the first version)? It is valid only where
  every replicate's mass in A lies where the fitted model's does: for regions far in the
  tail (the simulated criticality, ``btn > 0.7``) a replicate whose tail points elsewhere
  gets weights near 0 on every sample and its P_b(A) collapses (lower bound ~1e-30
  measured on the TNO model). Hence
* ``pooled_interval(model, region, seed, rare)``, the "model" interval: the replicates'
  average density
  ``q = (1/B) sum_b p_b`` (one Gaussian mixture of B K components, the same transforms) is
  sampled restricted to A and B (plain draws; when ``rare``, subset-is on q,
  ``sampler.methods.rare.rare_probability``, whose draws carry weights ``v_i = q / proposal``),
  and ``P_b(A and B) = sum_i v_i w_b(x_i) / n_draws``, ``w_b = p_b / q <= B`` over those
  samples: the proposal covers every replicate (defensive mixture; Hesterberg 1995,
  Technometrics 37(2)), so no weight is unbounded and no replicate is out of support.
  Its limit is resolution: replicate b gets about ``n P_b(A) / (B Q(A))`` of the n
  samples, so replicates far below the pooled mass are seen by few samples; each
  replicate's effective sample size (Kish, of ``v_i w_b``) is reported, and when more
  replicates than the interval's tail share (2.5 %) have fewer than ``min_ess`` the lower
  end is flagged as not resolved (``lower_resolved: false``: estimates from few
  effective samples tend to be low, so that end is likely too low, i.e. conservative).
  ``per_replicate=True`` resolves it by one subset-is run per unresolved replicate
  (docs/sampler.md: 0.4-1 s each on ``btn > 0.7``). The rare path was plain subset
  simulation of q before: biased low 30-100x on ``btn > 0.7`` (its chains missed the
  replicates whose tail lies elsewhere; checked against 10^6 plain draws of one
  replicate), with effective sample sizes that looked fine because the chains'
  duplicated states counted as distinct samples (still selectable: ``subset=`` a
  ``SubsetSampler``).
* ``bootstrap_ci``: the interval from the replicates, percentile (default), bias-corrected,
  or basic / normal on log P; measured coverage in docs/sampler.md
  (``benchmarks/bench_bootstrap_coverage.py``).
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

from sampler._threads import single_threaded
from sampler.errors import ModelError

__all__ = ["bootstrap_fit", "log_density_z_boot", "pooled_model", "replicate_model"]

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
    model.check_fitted()
    n_boot = int(n_boot)
    if not 2 <= n_boot <= 10_000:
        raise ModelError(f"n_bootstrap: expected 2 ... 10000 replicates, got {n_boot}")
    if model.covariance_type != "full":
        raise ModelError("bootstrap: only covariance_type='full' models are supported")
    x = model.table_matrix(table, model.features_)
    z = model.to_z(x)
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


def pooled_model(model: Any) -> Any:
    """The average of the bootstrap replicates, ``q = (1/B) sum_b p_b``, as a model of the
    same class (B K components, weights ``w_bk / B``, the fitted model's transforms, fixed
    values and lane width; no replicates of its own)."""
    boot = getattr(model, "bootstrap_", None)
    if not boot:
        raise ModelError("this model has no bootstrap replicates: fit with n_bootstrap > 0")
    w = np.asarray(boot["weights"], dtype=np.float64)
    b = w.shape[0]
    m = np.asarray(boot["means"], dtype=np.float64)
    c = np.asarray(boot["covariances"], dtype=np.float64)
    d = m.shape[-1]
    data = model.to_dict()
    data["bootstrap"] = None
    pooled = type(model).from_dict(data)
    weights = w.reshape(-1) / b
    keep = weights > 0
    pooled.set_mixture(weights[keep] / weights[keep].sum(), m.reshape(-1, d)[keep],
                        c.reshape(-1, d, d)[keep])
    pooled.n_components_ = int(keep.sum())
    return pooled


def replicate_model(model: Any, b: int) -> Any:
    """Bootstrap replicate ``b`` as a model of the same class (its mixture, the fitted
    model's transforms, fixed values and lane width; no replicates of its own)."""
    boot = getattr(model, "bootstrap_", None)
    if not boot:
        raise ModelError("this model has no bootstrap replicates: fit with n_bootstrap > 0")
    data = model.to_dict()
    data["bootstrap"] = None
    rep = type(model).from_dict(data)
    w = np.asarray(boot["weights"][b], dtype=np.float64)
    keep = w > 0
    rep.set_mixture(w[keep] / w[keep].sum(), np.asarray(boot["means"][b])[keep],
                     np.asarray(boot["covariances"][b])[keep])
    rep.n_components_ = int(keep.sum())
    return rep
