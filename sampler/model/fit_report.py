"""The fit report of a ``CutInGMM``: held-out log-likelihood, KS statistics, out-of-bounds
mass, and the text ``scengen fit`` prints (BIC curve and report)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from sklearn.model_selection import KFold

from sampler.intervals import clopper_pearson
from sampler.region.constraints import PHYSICAL_BOUNDS, Region, derive

if TYPE_CHECKING:
    from sampler.model.gmm import CutInGMM

__all__ = ["fit_report", "report_text"]

FloatArray = NDArray[np.float64]


def fit_report(model: CutInGMM, x: FloatArray, z: FloatArray, logj: FloatArray,
               bic: float) -> dict[str, Any]:
    """The fit report of ``CutInGMM.fit`` (see its docstring for the keys)."""
    n = x.shape[0]
    folds = min(int(model.cv_folds), n // 2)
    tails = _TailCalibration(model, x)
    per_fold = _heldout(model, z, logj, folds, tails)
    rng = np.random.default_rng(int(model.random_state))
    m = int(model.n_report_samples)
    draws = model.sample(m, rng)
    ks = {}
    for j, f in enumerate(model.features_):
        res = stats.ks_2samp(x[:, j], draws[:, j])
        ks[f] = {"statistic": float(res.statistic), "pvalue": float(res.pvalue)}
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
        "tail_calibration": tails.result(),
        "outside_bounds": _outside_bounds(model, draws),
    }


def _heldout(model: CutInGMM, z: FloatArray, logj: FloatArray, folds: int,
             tails: _TailCalibration) -> list[float]:
    """K-fold cross-validation with the chosen K: the held-out log-likelihood per row of
    each fold (NaN where the fit failed), original units; each fold's mixture also goes
    to ``tails``."""
    per_fold = []
    kf = KFold(n_splits=folds, shuffle=True, random_state=int(model.random_state))
    for fold, (train, test) in enumerate(kf.split(z)):
        gm, _, _err = model._fit_gm(model.n_components_, z[train])
        if gm is None:
            per_fold.append(float("nan"))
            continue
        per_fold.append(float(np.mean(gm.score_samples(z[test]) + logj[test])))
        tails.add_fold(gm, test, np.random.default_rng([int(model.random_state), fold]))
    return per_fold


def _outside_bounds(model: CutInGMM, draws: FloatArray) -> dict[str, Any]:
    """The share of the model's draws outside the physical bounds, its interval and its
    split by bound."""
    m = draws.shape[0]
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
    return {"fraction": k_out / m, "ci95": [lo, hi], "per_bound": per_bound,
            "lane_width": model.lane_width_, "n_samples": m}


def report_text(model: CutInGMM) -> str:
    """Human-readable BIC curve and fit report (what ``scengen fit`` prints)."""
    model.check_fitted()
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
        lines.extend(tail_text(r.get("tail_calibration")))
    return "\n".join(lines)


#: quantities and data quantiles of the tail calibration (lower tails: the critical side)
TAIL_QUANTITIES = ("ttc", "thw", "gap")
TAIL_QUANTILES = (0.02, 0.05, 0.1, 0.25)


class _TailCalibration:
    """K-fold held-out exceedance probabilities: for thresholds at data quantiles of TTC,
    THW and gap, the fold model's P(q < t | physical bounds) (from its own draws) against
    the share of the fold's held-out rows with q < t; pooled over the folds."""

    def __init__(self, model: CutInGMM, x: FloatArray) -> None:
        self.model = model
        self.m = max(1000, int(model.n_report_samples))
        q = derive(model.params_matrix(x), TAIL_QUANTITIES, lane_width=model.lane_width_)
        self.data = q
        self.thresholds: dict[str, list[tuple[float, float]]] = {}
        for name in TAIL_QUANTITIES:
            v = q[name][np.isfinite(q[name])]
            if v.size < 20:
                continue
            ts = sorted({float(np.quantile(v, a)) for a in TAIL_QUANTILES})
            self.thresholds[name] = [(t, float(np.mean(q[name] < t))) for t in ts]
        self.rows: dict[tuple[str, float], dict[str, Any]] = {}

    def add_fold(self, gm: Any, test: Any, rng: np.random.Generator) -> None:
        model = self.model
        k = gm.n_components
        labels = np.minimum(np.searchsorted(np.cumsum(gm.weights_), rng.random(self.m),
                                            side="right"), k - 1)
        e = rng.standard_normal((self.m, model.n_features))
        z = np.empty_like(e)
        chol = np.linalg.cholesky(np.asarray(gm.covariances_))
        for j in range(k):
            idx = labels == j
            z[idx] = gm.means_[j] + e[idx] @ chol[j].T
        params = model.params_matrix(model.from_z(z))
        in_b = Region(lane_width=model.lane_width_).in_bounds(params)
        q = derive(params, list(self.thresholds), lane_width=model.lane_width_)
        n_b = max(1, int(in_b.sum()))
        for name, ts in self.thresholds.items():
            for t, _share in ts:
                row = self.rows.setdefault((name, t), {"model": [], "k": 0, "n": 0})
                row["model"].append(float(np.sum((q[name] < t) & in_b) / n_b))
                row["k"] += int(np.sum(self.data[name][test] < t))
                row["n"] += len(test)

    def result(self) -> dict[str, Any]:
        out = []
        for name, ts in self.thresholds.items():
            for t, share in ts:
                row = self.rows.get((name, t))
                if not row or not row["n"]:
                    continue
                p_model = float(np.mean(row["model"]))
                lo, hi = clopper_pearson(row["k"], row["n"])
                out.append({"quantity": name, "threshold": t, "data_share": share,
                            "model_p": p_model, "heldout_share": row["k"] / row["n"],
                            "heldout_ci95": [lo, hi], "inside_ci": bool(lo <= p_model <= hi)})
        return {"draws_per_fold": self.m, "quantiles": list(TAIL_QUANTILES), "rows": out}


def tail_text(tc: Any) -> list[str]:
    """Lines of the tail calibration table (empty when there is none)."""
    if not tc or not tc.get("rows"):
        return []
    lines = ["tail calibration (k-fold held out; P(q < t): model vs held-out share, 95% CI):"]
    for r in tc["rows"]:
        mark = "" if r["inside_ci"] else "  <- outside"
        lines.append(f"  {r['quantity']:4s} < {r['threshold']:8.3f}  model {r['model_p']:.4f}"
                     f"  held out {r['heldout_share']:.4f} [{r['heldout_ci95'][0]:.4f}, "
                     f"{r['heldout_ci95'][1]:.4f}]{mark}")
    return lines
