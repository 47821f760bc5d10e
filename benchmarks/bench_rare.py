"""Rare-event benchmark: the acceleration factor of subset simulation and the project's
samplers over naive Monte Carlo, on the model fitted to the embedded TNO cut-ins.

For regions at P(A) of about 1e-3, 1e-4 and 1e-5 it prints, all in one run:

* the brute-force reference: naive Monte Carlo with ``N_ref = max(1e6, 300 / p)`` plain
  model draws (capped by ``--max-ref``), P(A and B) = hits / N_ref and its exact 95 %
  interval;
* per method, over ``--reps`` seeded repetitions: the mean estimate, the measured CoV
  (standard deviation over the repetitions / the reference), the mean number of
  limit-state evaluations (region memberships; for subset simulation its limit-state
  evaluations), and the acceleration = evaluations naive Monte Carlo needs for the same
  CoV, ``(1 - p) / (p CoV^2)``, divided by the evaluations used;
* whether each repetition's estimate lies inside 2 reported CoV of the reference.

Methods: ``subset`` (subset simulation, ``sampler.subset``), ``auto`` (the sampler's
default path: rejection from the half-space envelope when the region has one, subset
simulation when the pilot finds too few hits, importance sampling otherwise) and
``mcmc`` (the pilot plus an MCMC run: P(A) from the pilot's hits or importance sampling).

Regions: ``thw`` (kinematic, no half-space envelope: the fair comparison with naive MC),
``ttc`` (has an envelope) and, when the constraint language has the simulated criticality
(``btn``, issue 11), ``btn`` thresholds. Thresholds were chosen by a pilot scan to give the
wanted P(A) orders on this model.

Targets (issue 12): acceleration >= 100 at 1e-4 and >= 1000 at 1e-5, estimates inside the
brute-force interval.

Usage: ``.venv/bin/python benchmarks/bench_rare.py [--reps 20] [--max-ref 2e7]
[--families thw,ttc]``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: family -> [(constraint, target order of P(A))]
REGIONS: dict[str, list[tuple[str, float]]] = {
    "thw": [("thw<0.19", 1e-3), ("thw<0.13", 1e-4), ("thw<0.115", 1e-5)],
    "ttc": [("ttc<3", 1e-3), ("ttc<2.1", 1e-4), ("ttc<1.4", 1e-5)],
    "btn": [("btn>0.1", 1e-3), ("btn>0.3", 1e-4), ("btn>0.5", 1e-5)],
}

_COUNT = {"rows": 0}


def _count_contains() -> None:
    """Count every region-membership evaluation (the limit state of rejection / MCMC)."""
    from sampler.constraints import Region

    original = Region.contains

    def contains(self: Any, params: Any) -> Any:
        out = original(self, params)
        _COUNT["rows"] += int(np.asarray(out).shape[0])
        return out

    Region.contains = contains  # type: ignore[method-assign]


def _reference(model: Any, region: Any, p_guess: float, max_ref: float,
               seed: int) -> tuple[float, float, float, int]:
    from sampler.intervals import clopper_pearson

    n_ref = int(min(max_ref, max(1e6, 300.0 / p_guess)))
    if n_ref * p_guess < 30:  # fewer than ~30 expected hits: no usable brute force
        return math.nan, math.nan, math.nan, 0
    rng = np.random.default_rng(seed)
    hits = done = 0
    while done < n_ref:
        b = min(1 << 20, n_ref - done)
        x = model.params_matrix(model.sample(b, rng))
        hits += int(region.contains(x).sum())
        done += b
    lo, hi = clopper_pearson(hits, n_ref)
    return hits / n_ref, lo, hi, n_ref


def _run(model: Any, constraint: str, method: str, seed: int) -> tuple[float, float, int]:
    """One repetition: (P(A and B), reported CoV, evaluations)."""
    from sampler.constraints import Region
    from sampler.problem import Problem
    from sampler.sampleset import sample
    from sampler.subset import SubsetSampler

    if method == "subset":
        region = Region.from_constraints([constraint], lane_width=model.lane_width_)
        problem = Problem(model, region, use_envelope=False)
        res = SubsetSampler().run(problem, 1, np.random.default_rng(seed))
        return res.probability, res.cov_upper, res.n_evaluations
    _COUNT["rows"] = 0
    ss = sample(model, [constraint], 200, seed=seed, method=method)
    p = ss.p_region
    evals = _COUNT["rows"] if p.method != "subset" else p.n_draws + _COUNT["rows"]
    return p.p_joint, (p.cov if p.cov is not None else math.nan), evals


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--max-ref", type=float, default=2e7,
                        help="largest brute-force reference (kinematic regions)")
    parser.add_argument("--max-ref-crit", type=float, default=1e6,
                        help="largest brute-force reference for the simulated criticality")
    parser.add_argument("--families", default="thw,ttc,btn")
    parser.add_argument("--methods", default="subset,auto,mcmc")
    args = parser.parse_args()

    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM
    from sampler.constraints import QUANTITY_NAMES, Region

    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} "
          f"(uptime: {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    model = CutInGMM(random_state=0).fit(default_parameter_table(), source="embedded")
    print(f"model: TNO cut-ins, K = {model.n_components_}")
    _count_contains()
    families = [f for f in args.families.split(",") if f]
    rows = []
    for fam in families:
        first = REGIONS[fam][0][0]
        name = first.split("<")[0].split(">")[0]
        if name not in QUANTITY_NAMES:
            print(f"family {fam}: quantity {name!r} not in the constraint language yet: "
                  "skipped")
            continue
        for constraint, p_guess in REGIONS[fam]:
            region = Region.from_constraints([constraint], lane_width=model.lane_width_)
            t = time.perf_counter()
            cap = args.max_ref_crit if fam == "btn" else args.max_ref
            p_ref, lo, hi, n_ref = _reference(model, region, p_guess, cap, 12345)
            t_ref = time.perf_counter() - t
            if n_ref:
                print(f"\n{constraint}: reference P(A and B) = {p_ref:.3g} "
                      f"[{lo:.3g}, {hi:.3g}] from {n_ref:.3g} naive draws ({t_ref:.0f} s)",
                      flush=True)
            else:
                print(f"\n{constraint}: brute force unaffordable (P ~ {p_guess:g}, cap "
                      f"{cap:g} draws): reference = mean of the subset repetitions, CoV = "
                      "their spread", flush=True)
            if n_ref and p_ref == 0:
                print("  no hit: reference unusable; raise --max-ref")
                continue
            print(f"  {'method':8s} {'mean P':>10s} {'CoV meas':>9s} {'CoV rep':>8s} "
                  f"{'evals':>9s} {'naive eq':>10s} {'accel':>8s} {'in 2CoV':>8s} "
                  f"{'in ref CI':>9s} {'s/rep':>6s}")
            for method in args.methods.split(","):
                est, cov, ev = [], [], []
                t = time.perf_counter()
                for rep in range(args.reps):
                    try:
                        p, c, e = _run(model, constraint, method, 1000 + rep)
                    except Exception as exc:  # report and go on: a benchmark, not a test
                        print(f"  {method:8s} failed: {str(exc).splitlines()[0][:120]}")
                        break
                    est.append(p)
                    cov.append(c)
                    ev.append(e)
                if len(est) < 2:
                    continue
                dt = (time.perf_counter() - t) / len(est)
                e_arr, c_arr = np.array(est), np.array(cov)
                if not n_ref:  # no brute force: the first method's mean is the reference
                    p_ref = p_ref if math.isfinite(p_ref) else float(e_arr.mean())
                    lo = hi = math.nan
                cov_meas = float(np.sqrt(np.mean((e_arr - p_ref) ** 2)) / p_ref)
                evals = float(np.mean(ev))
                naive = (1 - p_ref) / (p_ref * max(cov_meas, 1e-12) ** 2)
                accel = naive / evals
                in2 = float(np.mean(np.abs(e_arr - p_ref) <= 2 * c_arr * p_ref))
                in_ci = float(np.mean((e_arr >= lo) & (e_arr <= hi)))
                print(f"  {method:8s} {e_arr.mean():10.3g} {cov_meas:9.3f} "
                      f"{np.nanmean(c_arr):8.3f} {evals:9.0f} {naive:10.3g} {accel:8.1f} "
                      f"{in2:8.2f} {in_ci:9.2f} {dt:6.2f}", flush=True)
                rows.append((constraint, method, p_ref, e_arr.mean(), cov_meas, evals, accel))
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")
    print("CoV meas: root mean square error over the repetitions / reference; CoV rep: the "
          "method's own reported CoV (subset: the conservative bound); naive eq: naive "
          "evaluations for CoV meas; accel = naive eq / evals.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
