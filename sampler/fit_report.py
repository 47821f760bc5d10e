"""The fit report of a ``CutInGMM``: held-out log-likelihood, KS statistics, out-of-bounds
mass, and the text ``scengen fit`` prints (BIC curve and report)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from sklearn.model_selection import KFold

from sampler.constraints import PHYSICAL_BOUNDS, Region
from sampler.intervals import clopper_pearson

if TYPE_CHECKING:
    from sampler.model import CutInGMM

__all__ = ["fit_report", "report_text"]

FloatArray = NDArray[np.float64]


def fit_report(model: CutInGMM, x: FloatArray, z: FloatArray, logj: FloatArray,
               bic: float) -> dict[str, Any]:
    """The fit report of ``CutInGMM.fit`` (see its docstring for the keys)."""
    n = x.shape[0]
    folds = min(int(model.cv_folds), n // 2)
    per_fold = []
    kf = KFold(n_splits=folds, shuffle=True, random_state=int(model.random_state))
    for train, test in kf.split(z):
        gm, _, _err = model._fit_gm(model.n_components_, z[train])
        if gm is None:
            per_fold.append(float("nan"))
            continue
        per_fold.append(float(np.mean(gm.score_samples(z[test]) + logj[test])))
    rng = np.random.default_rng(int(model.random_state))
    m = int(model.n_report_samples)
    draws = model.sample(m, rng)
    ks = {}
    for j, f in enumerate(model.features_):
        res = stats.ks_2samp(x[:, j], draws[:, j])
        ks[f] = {"statistic": float(res.statistic), "pvalue": float(res.pvalue)}
    region = Region(lane_width=model.lane_width_)
    params = model.params_matrix(draws)
    inside = region.in_bounds(params)
    k_out = int((~inside).sum())
    lo, hi = clopper_pearson(k_out, m)
    # each outside draw is attributed to the first bound it violates (in the order of
    # PHYSICAL_BOUNDS), so the shares add up to the total
    viol = region.violations(params)
    remaining = np.ones(m, dtype=bool)
    per_bound = {}
    for b in PHYSICAL_BOUNDS:
        hit = viol[str(b)] & remaining
        per_bound[str(b)] = float(hit.sum() / m)
        remaining &= ~hit
    pf = np.asarray(per_fold)
    return {
        "n_rows": n,
        "k": model.n_components_,
        "bic": bic,
        "loglik_per_row": float(np.mean(model.log_density(x))),
        "heldout_loglik_per_row": {
            "mean": float(np.nanmean(pf)) if np.isfinite(pf).any() else None,
            "std": float(np.nanstd(pf)) if np.isfinite(pf).any() else None,
            "folds": folds,
            "per_fold": [None if not math.isfinite(v) else v for v in per_fold],
        },
        "ks": ks,
        "outside_bounds": {"fraction": k_out / m, "ci95": [lo, hi],
                           "per_bound": per_bound, "lane_width": model.lane_width_,
                           "n_samples": m},
    }

def report_text(model: CutInGMM) -> str:
    """Human-readable BIC curve and fit report (what ``scengen fit`` prints)."""
    model._check_fitted()
    lines = ["BIC curve (original units, lower is better):"]
    for c in model.bic_curve_:
        mark = "  <- chosen" if c["k"] == model.n_components_ else ""
        if c["bic"] is None:
            lines.append(f"  K={c['k']:2d}  failed: {c['error']}")
        else:
            conv = "" if c["converged"] else "  (not converged)"
            lines.append(f"  K={c['k']:2d}  BIC={c['bic']:12.2f}{conv}{mark}")
    r = getattr(model, "fit_report_", None)
    if r:
        h = r["heldout_loglik_per_row"]
        lines.append(f"chosen K = {r['k']}  ({r['n_rows']} rows, {len(model.features_)} "
                     f"features)")
        lines.append(f"log-likelihood per row: in-sample {r['loglik_per_row']:.3f}, "
                     f"held-out {h['mean']:.3f} +- {h['std']:.3f} ({h['folds']}-fold CV)"
                     if h["mean"] is not None else "held-out log-likelihood: failed")
        lines.append("KS statistic data vs model samples:")
        for f, v in r["ks"].items():
            lines.append(f"  {f:6s} D={v['statistic']:.3f}  p={v['pvalue']:.3g}")
        ob = r["outside_bounds"]
        lines.append(f"model mass outside physical bounds: {ob['fraction']:.4f} "
                     f"(95% CI {ob['ci95'][0]:.4f}-{ob['ci95'][1]:.4f}, "
                     f"{ob['n_samples']} draws)")
        for name, frac in ob["per_bound"].items():
            if frac > 0:
                lines.append(f"  first violated bound {name}: {frac:.4f}")
    return "\n".join(lines)
