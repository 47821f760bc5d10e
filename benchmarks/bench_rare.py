"""Rare-event benchmark: the acceleration factor of subset simulation, subset-is and the
sampler's ``auto`` path over naive Monte Carlo, on the model fitted to the embedded TNO
cut-ins, for regions of the simulated criticality (issue 12 item 5). Asserts nothing.

Brute-force references, computed in the same run (one pass each, shared by the regions):

* ``naive``: ``--naive`` plain model draws; every draw inside the physical bounds gets its
  criticality quantities; P(A and B) = hits / draws with its exact (Clopper-Pearson) 95 %
  interval;
* ``envelope`` (regions with ``ttc<3``): ``--envelope`` exact draws of the model restricted
  to the half-space envelope S of ``ttc<3`` (``sampler.methods.envelope``, P(S) exact); the draws
  inside ``ttc<3`` get their criticality quantities; P(A and B) = P(S) hits / draws, the
  interval P(S) times the exact one. Still naive Monte Carlo (stratified by an exactly
  known set), so it is unbiased with an exact interval, far cheaper for these regions.

Per method and region, over ``--reps`` seeded repetitions: the mean estimate; ``CoV``,
the spread of the repetitions (standard deviation / mean); ``CoV ref``, the root mean
square error against the reference / the reference (it includes the reference's own
error, so it bounds what a finite reference can show); the mean reported CoV; the mean
number of criticality evaluations (every row simulated: the subset levels, the adaptation
and the importance draws; for ``auto`` also the pilot and P(A)); the acceleration = the
naive draws needed for the same CoV, ``(1 - p) / (p CoV^2)``, divided by the evaluations
used (``accel``: from ``CoV``; ``accel ref``: from ``CoV ref``); ``accel wall``, the same
in seconds: naive Monte Carlo's seconds for ``CoV ref`` (its cost per draw measured in the
run: drawing, the bounds, and the simulation of the share it simulates) over the method's
seconds per repetition; ``accel sim``, the fair
figure for the simulations: ``accel ref`` times the share of naive draws that naive Monte
Carlo has to simulate (those inside the physical bounds and the region's kinematic
constraints, such as ``ttc<3``: it checks them first, for free; from the naive pass; the
same as ``accel ref`` for a kinematic region); the share of repetitions
within 2 reported CoV of the reference; whether the mean lies inside the reference's
interval, and the share of single estimates that do.

Methods: ``subset`` (plain subset simulation, 2,000 points per level), ``subset-is``
(``sampler.methods.rare`` defaults: ``stratify="auto"``, which stratifies the TNO model),
``subset-is-plain`` (one subset-is on
the whole model, ``stratify="never"``), ``subset-is-strat`` (one per stratum of the model,
component x cut-in side, ``stratify="always"``), ``auto``
(``sample(model, constraints, 100, seed)``: its P(A and B); evaluations counted through
``Region.contains`` and the limit states; for kinematic regions, which simulate nothing,
the limit-state rows).

Targets (issue 12): acceleration >= 100 at 1e-4 and >= 1000 at 1e-5, estimates inside
the brute-force interval. Read them on ``accel sim``: for ``ttc<3 & ...`` regions naive
Monte Carlo simulates only the ~1e-3 of its draws inside ``ttc<3``, so ``accel ref``
overstates the gain there by about 1000.

Usage: ``.venv/bin/python benchmarks/bench_rare.py [--reps 20] [--naive 3e6]
[--envelope 4e6] [--methods subset,subset-is,auto] [--regions 0,1,2]
[--refs-cache /tmp/rare-refs.pkl]``; ``BENCH_RARE_SETTINGS='{"strat_split_side": false}'``
(JSON) passes settings to ``SubsetISSampler`` (experiments).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

#: (constraints, target order of P(A and B), reference pass)
REGIONS: list[tuple[list[str], float, str]] = [
    (["btn>0.15"], 1e-3, "naive"),
    (["btn>0.3"], 1e-4, "naive"),
    (["ttr_true<2.8"], 1e-4, "naive"),
    (["ttc<3", "btn>0.3"], 1e-4, "envelope"),
    (["ttc<3", "btn>0.4"], 1e-5, "envelope"),
    (["ttc<3", "ttr_true<2"], 1e-5, "envelope"),
    (["ttc<3", "btn>0.5"], 1e-5, "envelope"),
    (["ttc<3", "btn>0.7", "btn<1"], 1e-7, "envelope"),
    # several modes (left and right cut-ins, several components): kinematic, inside ttc<3
    (["ttc<2"], 1e-4, "envelope"),
    # standalone (not inside ttc<3) at ~1e-5: naive references need --naive 1e7
    (["btn>0.4"], 1e-5, "naive"),
    (["ttr_true<2"], 1e-5, "naive"),
    # the careful driver cannot prevent it (~1e-8): needs --envelope 6e7 (~300 hits)
    (["ttc<3", "btn>=1"], 1e-8, "envelope"),
]

_COUNT = {"rows": 0}


def _count_evaluations() -> None:
    """Count every row whose criticality quantities are simulated (the costly limit
    state, whichever path evaluates it)."""
    import sampler.methods.subset as ss
    import sampler.region.constraints as sc

    original = sc.criticality_quantities

    def counted(params: Any, *args: Any, **kwargs: Any) -> Any:
        _COUNT["rows"] += int(np.asarray(params).shape[0])
        return original(params, *args, **kwargs)

    sc.criticality_quantities = counted
    ss.criticality_quantities = counted


def _naive_costs(model: Any, n: int = 1 << 16) -> dict[str, float]:
    """Seconds per draw of naive Monte Carlo's parts, measured in this run: drawing and
    the physical bounds; the simulation per simulated row without and with the TTR scan
    (a ``btn`` region needs no TTR scan, a ``ttr_true`` region does)."""
    from sampler.region.constraints import Region
    from sampler.region.criticality import criticality_quantities

    rng = np.random.default_rng(2024)
    bounds = Region.from_constraints([], lane_width=model.lane_width_)
    criticality_quantities(model.params_matrix(model.sample(64, rng)), model.lane_width_)
    t = time.perf_counter()
    x = model.params_matrix(model.sample(n, rng))
    x = x[bounds.in_bounds(x)]
    out = {"draw": (time.perf_counter() - t) / n}
    for key, ttr in (("btn", False), ("ttr", True)):
        rows = x[: n // 4 if ttr else n]
        t = time.perf_counter()
        criticality_quantities(rows, model.lane_width_, with_ttr=ttr)
        out[key] = (time.perf_counter() - t) / rows.shape[0]
    return out


def _references(model: Any, n_naive: int, n_env: int, seed: int) -> dict[str, Any]:
    """The two brute-force passes: per pass the draws, P(S) and the rows' quantities."""
    from sampler.methods.problem import Problem
    from sampler.region.constraints import Region, derive
    from sampler.region.criticality import criticality_quantities

    lw = model.lane_width_
    out: dict[str, Any] = {}
    rng = np.random.default_rng(seed)
    t = time.perf_counter()
    bounds = Region.from_constraints([], lane_width=lw)
    rows: list[np.ndarray] = []
    done = 0
    while done < n_naive:
        x = model.params_matrix(model.sample(min(1 << 18, n_naive - done), rng))
        done += x.shape[0]
        rows.append(x[bounds.in_bounds(x)])
    x = np.concatenate(rows)
    q = criticality_quantities(x, lw)
    q["ttc"] = derive(x, ["ttc"], lane_width=lw)["ttc"]
    out["naive"] = {"draws": n_naive, "mass": 1.0, "q": q, "params": x,
                    "seconds": time.perf_counter() - t}
    t = time.perf_counter()
    problem = Problem(model, Region.from_constraints(["ttc<3"], lane_width=lw))
    assert problem.envelope is not None
    rows = []
    done = 0
    while done < n_env:
        z = problem.draw_z(min(1 << 18, n_env - done), rng)
        done += z.shape[0]
        xx = problem.params(z)
        rows.append(xx[problem.region.contains(xx)])
    x = np.concatenate(rows)
    q = criticality_quantities(x, lw)
    q["ttc"] = derive(x, ["ttc"], lane_width=lw)["ttc"]
    out["envelope"] = {"draws": n_env, "mass": problem.envelope.mass, "q": q, "params": x,
                       "seconds": time.perf_counter() - t}
    return out


def _reference(refs: dict[str, Any], constraints: list[str], kind: str,
               lane_width: float) -> tuple[float, float, float, int, int]:
    from sampler.intervals import clopper_pearson
    from sampler.region.constraints import parse_constraint

    r = refs[kind]
    inside = np.ones(r["params"].shape[0], dtype=bool)
    for text in constraints:
        c = parse_constraint(text)
        inside &= c.mask(r["q"][c.name])
    k = int(inside.sum())
    lo, hi = clopper_pearson(k, r["draws"])
    m = r["mass"]
    return m * k / r["draws"], m * lo, m * hi, k, r["draws"]


def _sim_share(refs: dict[str, Any], constraints: list[str]) -> float:
    """The share of plain model draws that naive Monte Carlo has to simulate for the
    region: those inside the physical bounds and inside its kinematic constraints (which
    cost no simulation, so a naive run checks them first), from the naive pass. 1 for a
    kinematic region (nothing is simulated: the cost unit is a limit-state row there)."""
    from sampler.region.constraints import parse_constraint
    from sampler.region.criticality import CRITICALITY_QUANTITIES

    cons = [parse_constraint(text) for text in constraints]
    if not any(c.name in CRITICALITY_QUANTITIES for c in cons):
        return 1.0
    r = refs["naive"]
    keep = np.ones(r["params"].shape[0], dtype=bool)  # the pass kept in-bounds rows only
    for c in cons:
        if c.name not in CRITICALITY_QUANTITIES:
            keep &= c.mask(r["q"][c.name])
    return float(keep.sum()) / float(r["draws"])


def _run(model: Any, constraints: list[str], method: str, seed: int
         ) -> tuple[float, float, int]:
    """One repetition: (P(A and B), reported CoV, criticality evaluations)."""
    from sampler.methods.problem import Problem
    from sampler.methods.rare import SubsetISSampler
    from sampler.methods.subset import SubsetSampler
    from sampler.region.constraints import Region
    from sampler.sampling import sample

    _COUNT["rows"] = 0
    rng = np.random.default_rng(seed)
    if method.startswith("subset"):
        region = Region.from_constraints(constraints, lane_width=model.lane_width_)
        problem = Problem(model, region, use_envelope=False)
        if method == "subset":
            res: Any = SubsetSampler().run(problem, 1, rng)
            return res.probability, res.cov_upper, _COUNT["rows"] or problem.n_evals
        stratify = {"subset-is": "auto", "subset-is-plain": "never",
                    "subset-is-strat": "always"}[method]
        kw = json.loads(os.environ.get("BENCH_RARE_SETTINGS", "{}"))  # experiments
        # flat settings (stratify, n_is, ...) go through from_settings since the
        # sampler's settings were grouped (importance, stratification, chains)
        res = SubsetISSampler.from_settings(stratify=stratify, **kw).run(problem, rng)
        # kinematic regions simulate nothing: their limit-state evaluations instead
        return res.probability, res.cov, _COUNT["rows"] or problem.n_evals
    ss = sample(model, constraints, 100, seed=seed, method=method)
    p = ss.p_region
    return p.p_joint, (p.cov if p.cov is not None else math.nan), _COUNT["rows"]


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--naive", type=float, default=3e6, help="plain model draws")
    parser.add_argument("--envelope", type=float, default=4e6,
                        help="draws of the model restricted to the ttc<3 envelope")
    parser.add_argument("--methods", default="subset,subset-is,auto")
    parser.add_argument("--refs-cache", default="",
                        help="pickle file for the brute-force passes (reused when the "
                             "draw counts and the model match)")
    parser.add_argument("--regions", default=",".join(str(i) for i in range(len(REGIONS))))
    args = parser.parse_args()

    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM

    def load() -> str:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())

    print(f"machine: {os.cpu_count()} cores, load average {load()}", flush=True)
    model = CutInGMM(random_state=0).fit(default_parameter_table(), source="embedded")
    print(f"model: TNO cut-ins, K = {model.n_components_}", flush=True)
    t = time.perf_counter()
    cache = Path(args.refs_cache) if args.refs_cache else None
    key = f"{int(args.naive)}-{int(args.envelope)}-{model.training_['sha256']}"
    if cache is not None and cache.exists() and pickle.loads(cache.read_bytes())[0] == key:
        refs = pickle.loads(cache.read_bytes())[1]
        print(f"references read from {cache} (computed by an earlier run of this script)")
    else:
        refs = _references(model, int(args.naive), int(args.envelope), 12345)
        if cache is not None:
            cache.write_bytes(pickle.dumps((key, refs)))
    print(f"references: {int(args.naive):,} naive draws ({refs['naive']['seconds']:.0f} s), "
          f"{int(args.envelope):,} envelope draws, P(S) = {refs['envelope']['mass']:.4g} "
          f"({refs['envelope']['seconds']:.0f} s); load {load()}", flush=True)
    _count_evaluations()
    costs = _naive_costs(model)
    print(f"naive Monte Carlo's cost, measured now: {costs['draw'] * 1e6:.2f} us per draw "
          f"(drawing and the physical bounds), {costs['btn'] * 1e6:.1f} us per simulated "
          f"row without the TTR scan, {costs['ttr'] * 1e6:.1f} us with it", flush=True)
    table = []
    for i in (int(s) for s in args.regions.split(",") if s):
        constraints, _order, kind = REGIONS[i]
        name = " & ".join(constraints)
        p_ref, lo, hi, k, n_ref = _reference(refs, constraints, kind, model.lane_width_)
        print(f"\n{name}: reference P(A and B) = {p_ref:.3g} [{lo:.3g}, {hi:.3g}] "
              f"({k} hits of {n_ref:,} {kind} draws)", flush=True)
        if k == 0:
            print("  no hit: reference unusable")
            continue
        f_sim = _sim_share(refs, constraints)
        print(f"  naive Monte Carlo simulates {f_sim:.4g} of its draws (inside the physical "
              "bounds and the kinematic constraints)", flush=True)
        per_draw = costs["draw"] + f_sim * costs[
            "ttr" if any(c.startswith("ttr_true") for c in constraints) else "btn"]
        print(f"  {'method':15s} {'mean P':>10s} {'CoV':>6s} {'CoV ref':>7s} {'CoV rep':>7s} "
              f"{'evals':>8s} {'accel':>8s} {'accel ref':>9s} {'accel sim':>9s} {'in 2CoV':>7s} "
              f"{'mean in CI':>10s} {'in CI':>6s} {'s/rep':>6s} {'accel wall':>10s}")
        for method in args.methods.split(","):
            est, cov, ev = [], [], []
            t = time.perf_counter()
            reps = args.reps if method != "auto" else max(2, args.reps // 4)
            for rep in range(reps):
                try:
                    p, c, e = _run(model, constraints, method, 1000 + rep)
                except Exception as exc:  # report and go on: a benchmark, not a test
                    print(f"  {method:15s} failed: {str(exc).splitlines()[0][:120]}")
                    break
                est.append(p)
                cov.append(c)
                ev.append(e)
            if len(est) < 2:
                continue
            dt = (time.perf_counter() - t) / len(est)
            e_arr, c_arr = np.array(est), np.array(cov)
            mean = float(e_arr.mean())
            cov_spread = float(e_arr.std(ddof=1) / mean)
            cov_ref = float(np.sqrt(np.mean((e_arr - p_ref) ** 2)) / p_ref)
            evals = float(np.mean(ev))
            accel = (1 - mean) / (mean * max(cov_spread, 1e-12) ** 2) / evals
            accel_ref = (1 - p_ref) / (p_ref * max(cov_ref, 1e-12) ** 2) / evals
            in2 = float(np.mean(np.abs(e_arr - p_ref) <= 2 * c_arr * e_arr))
            mean_in = "yes" if lo <= mean <= hi else "no"
            in_ci = float(np.mean((e_arr >= lo) & (e_arr <= hi)))
            # wall clock: naive Monte Carlo's seconds for the same CoV (measured per draw
            # above) over this method's seconds per repetition
            accel_wall = (1 - p_ref) / (p_ref * max(cov_ref, 1e-12) ** 2) * per_draw / dt
            print(f"  {method:15s} {mean:10.3g} {cov_spread:6.3f} {cov_ref:7.3f} "
                  f"{np.nanmean(c_arr):7.3f} {evals:8.0f} {accel:8.0f} {accel_ref:9.0f} "
                  f"{accel_ref * f_sim:9.1f} {in2:7.2f} {mean_in:>10s} {in_ci:6.2f} "
                  f"{dt:6.2f} {accel_wall:10.1f}", flush=True)
            table.append((name, p_ref, lo, hi, method, mean, cov_spread, cov_ref,
                          float(np.nanmean(c_arr)), evals, accel, accel_ref, accel_ref * f_sim,
                          in2, mean_in, len(est)))
    print(f"\nload average at the end: {load()}")
    print("\n| region | P(A and B) brute force [95 %] | method | mean P | CoV | CoV ref "
          "| CoV rep | evaluations | accel | accel ref | accel sim | in 2 CoV | mean in CI "
          "| reps |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for (name, p_ref, lo, hi, method, mean, cs, cr, cp, evals, accel, accel_ref, accel_sim,
         in2, mean_in, n) in table:
        print(f"| {name} | {p_ref:.3g} [{lo:.3g}, {hi:.3g}] | {method} | {mean:.3g} | "
              f"{cs:.3f} | {cr:.3f} | {cp:.3f} | {evals:,.0f} | {accel:,.0f} | "
              f"{accel_ref:,.0f} | {accel_sim:,.1f} | {in2:.2f} | {mean_in} | {n} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
