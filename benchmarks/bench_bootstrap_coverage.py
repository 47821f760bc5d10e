"""Coverage of the "model" interval of P(A) (``sampler.rates.bootstrap_interval.pooled_interval``).

Data sets of 250 rows are drawn from a known two-component mixture of (gap, dv); each is
fitted (K = 2), refitted B times (``bootstrap_fit``) and the model interval of
P(gap < c) is computed for c = 9 m (P = 1.6 %, plain draws) and c = 3 m (P = 2.3e-4,
subset simulation), where P under the true mixture is known in closed form. Printed per
region, B and interval method: the share of data sets whose interval covers the truth,
its binomial (Wilson) 95 % interval, and the median width hi / lo.

Two sources of the replicates' P(A):

* ``is``: what the code reports (importance sampling from the replicates' average, the
  fitted model's P(A) from the same samples);
* ``exact``: the replicates' and the fitted model's P(gap < c) in closed form (a half-space
  in z: sum_k w_k Phi((z_c - mu_k) / sigma_k)), i.e. the bootstrap method without the
  Monte-Carlo noise of the pooled importance sampling (a diagnostic).

Usage (from the repository root): ``PYTHONPATH=. .venv/bin/python
benchmarks/bench_bootstrap_coverage.py [--sets 40] [--seed 2000] [--boot 40 100]
[--exact-only]`` (one process; about 5 s per data set and B on the loaded 2-core machine,
0.3-1 s per data set with ``--exact-only``).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout this script is in (and its tests/)

from sampler.model import bootstrap_fit  # noqa: E402
from sampler.model.gmm import CutInGMM  # noqa: E402
from sampler.rates import INTERVALS, bootstrap_ci, pooled_interval  # noqa: E402
from sampler.region.constraints import Region  # noqa: E402
from tests.sampler.factories import base_params, closed_form, draw_table, true_p  # noqa: E402

CUTS = ((9.0, False), (3.0, True))


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson 95 % interval of a coverage share k / n (scipy's binomtest)."""
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return float(ci.low), float(ci.high)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=40)
    ap.add_argument("--seed", type=int, default=2000, help="data set i uses seed + i")
    ap.add_argument("--boot", type=int, nargs="+", default=[40, 100])
    ap.add_argument("--rows", type=int, default=250)
    ap.add_argument("--exact-only", action="store_true",
                    help="closed-form replicates only (no importance sampling: fast)")
    args = ap.parse_args()
    fixed = {k: v for k, v in base_params().items() if k not in ("gap", "dv")}
    b_max = max(args.boot)
    # results[(cut, B, source, method)] = list of (covered, width, lower_resolved)
    res: dict[tuple[float, int, str, str], list[tuple[bool, float]]] = {}
    unresolved: dict[tuple[float, int], int] = {}
    t0 = time.perf_counter()
    for i in range(args.sets):
        rng = np.random.default_rng(args.seed + i)
        table = draw_table(args.rows, rng)
        model = CutInGMM(features=["gap", "dv"], transforms={"gap": "identity"},
                         k_range=(2, 2), n_init=2, n_report_samples=200, cv_folds=2,
                         fixed=fixed).fit(table)
        # replicate seeds are spawned per replicate: the first B of b_max are the B refits
        full = bootstrap_fit(model, table, b_max, seed=args.seed + i)
        tr = model.transforms_[0]
        for b in args.boot:
            model.bootstrap_ = {**full, "n_boot": b,
                                **{k: full[k][:b] for k in ("weights", "means", "covariances")}}
            for cut, rare in CUTS:
                truth = true_p(cut)
                z_cut = (cut - tr.loc) / tr.scale
                region = Region.from_constraints([f"gap<{cut}"], physical_bounds=False)
                iv = None if args.exact_only else pooled_interval(model, region,
                                                                   args.seed + i, rare=rare)
                unresolved[(cut, b)] = unresolved.get((cut, b), 0) + (
                    iv is not None and not iv["lower_resolved"])
                exact = [closed_form(w, m, c, z_cut) for w, m, c in
                         zip(model.bootstrap_["weights"], model.bootstrap_["means"],
                             model.bootstrap_["covariances"], strict=True)]
                fit_exact = closed_form(model.weights_, model.means_, model.covariances_, z_cut)
                sources = [("exact", exact, fit_exact)]
                if iv is not None:
                    sources.insert(0, ("is", iv["replicates"], iv["fitted"]))
                for source, reps, est in sources:
                    for method in INTERVALS:
                        lo, hi = bootstrap_ci(reps, est, method)
                        res.setdefault((cut, b, source, method), []).append(
                            (lo <= truth <= hi, hi / lo if lo > 0 else math.inf))
        print(f"# data set {i + 1}/{args.sets}: {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"\n{args.sets} data sets of {args.rows} rows, seeds {args.seed}..."
          f"{args.seed + args.sets - 1}; {time.perf_counter() - t0:.0f} s\n")
    print("| region | P | B | replicates | method | coverage | Wilson 95 % | median hi/lo |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for cut, _ in CUTS:
        for b in args.boot:
            for source in ("is", "exact"):
                for method in INTERVALS:
                    if (cut, b, source, method) not in res:
                        continue
                    rows = res[(cut, b, source, method)]
                    k = sum(c for c, _ in rows)
                    lo, hi = wilson(k, len(rows))
                    print(f"| gap<{cut:g} | {true_p(cut):.2g} | {b} | {source} | {method} | "
                          f"{k / len(rows):.0%} | {lo:.0%}-{hi:.0%} | "
                          f"{np.median([w for _, w in rows]):.3g} |")
    for (cut, b), n in sorted(unresolved.items()):
        print(f"gap<{cut:g} B={b}: lower end not resolved in {n} of {args.sets}")


if __name__ == "__main__":
    main()
