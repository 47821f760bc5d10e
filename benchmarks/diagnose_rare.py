"""How well subset-is's final proposals cover a region, measured against brute-force hits
(the diagnosis in docs/sampler.md, "What the standalone btn regions still miss"). Asserts
nothing.

Reads the brute-force passes that ``bench_rare.py --refs-cache FILE`` wrote (run it
first with the same ``--naive`` / ``--envelope``). For ``--reps`` seeded runs of
``stratified_importance`` on the region, the hits inside it are exact draws of the model
restricted to A, so for each run and stratum s:

* the expected CoV of the run's estimate given its final proposals q_s (what the
  reported CoV estimates from the run's own draws):
  ``var = sum_s pi_s^2 (P_s E_{p_s|A}[p_s / q_s] - P_s^2) / n_s``, the expectation over
  the hits in the stratum's half-space, ``P_s`` from the reference (the strata's side
  split only: the hits are attributed to the stratum's component, which is right when
  one component holds nearly all of A, as on the regions measured);
* the share of A's mass where ``p_s / q_s > 100 P_s`` (under one of the run's draws
  expected there).

Prints the mean estimate / reference, its spread, the mean reported CoV, the expected
CoV (root mean square over the runs), that share, the share of runs inside 2 reported
CoV of the reference and the mean evaluations.

Usage: ``.venv/bin/python benchmarks/diagnose_rare.py --refs-cache /tmp/rare-refs-1e7.pkl
--naive 1e7 --envelope 3e6 -c 'btn>0.3' --kind naive --reps 30 [--settings JSON]``
(``--settings`` goes to ``stratified_importance``, e.g. ``'{"level_share": 0.0}'``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np


class _Counted:
    """A limit state that counts its rows."""

    def __init__(self, g: Callable[[np.ndarray], np.ndarray]) -> None:
        self.g = g
        self.n = 0

    def __call__(self, z: np.ndarray) -> np.ndarray:
        self.n += z.shape[0]
        return np.asarray(self.g(z))


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--refs-cache", required=True)
    parser.add_argument("--naive", type=float, default=1e7)
    parser.add_argument("--envelope", type=float, default=3e6)
    parser.add_argument("-c", "--constraint", action="append", required=True)
    parser.add_argument("--kind", choices=["naive", "envelope"], default="naive",
                        help="which brute-force pass holds the region (envelope: inside "
                             "ttc<3 only)")
    parser.add_argument("--reps", type=int, default=30)
    parser.add_argument("--settings", default="{}")
    args = parser.parse_args()

    from datasets.cutin_model import PARAM_NAMES
    from datasets.embedded import default_parameter_table
    from sampler import CutInGMM
    from sampler.methods.rare import StratumRun, stratified_importance
    from sampler.methods.subset import region_limit_state
    from sampler.region.constraints import Region, parse_constraint

    model = CutInGMM(random_state=0).fit(default_parameter_table(), source="embedded")
    key, refs = pickle.loads(Path(args.refs_cache).read_bytes())
    want = f"{int(args.naive)}-{int(args.envelope)}-{model.training_['sha256']}"
    if key != want:
        print(f"{args.refs_cache} holds other passes ({key}); run bench_rare.py with "
              f"--naive {args.naive:g} --envelope {args.envelope:g} first", file=sys.stderr)
        return 2
    ref = refs[args.kind]
    inside = np.ones(ref["params"].shape[0], dtype=bool)
    for text in args.constraint:
        c = parse_constraint(text)
        inside &= c.mask(ref["q"][c.name])
    k = int(inside.sum())
    if k == 0:
        print("no brute-force hit in the region", file=sys.stderr)
        return 2
    p_ref = ref["mass"] * k / ref["draws"]
    cols = [PARAM_NAMES.index(f) for f in model.features_]
    z_hits = model.to_z(ref["params"][inside][:, cols])
    region = Region.from_constraints(args.constraint, lane_width=model.lane_width_)
    settings = json.loads(args.settings)
    print(f"{' & '.join(args.constraint)}: reference {p_ref:.3g} ({k} hits); settings "
          f"{settings}", flush=True)
    rows = []
    t0 = time.perf_counter()
    for seed in range(1000, 1000 + args.reps):
        rng = np.random.default_rng(seed)
        counted = _Counted(region_limit_state(model, region, rng))
        runs: list[StratumRun] = []
        res = stratified_importance(model, counted, int(rng.integers(0, 2**31 - 1)),
                                    keep_runs=runs, **settings)
        var = 0.0
        missed = 0.0
        for run in runs:
            if run.stage is None:
                continue
            st = run.stratum
            ok = st.contains(z_hits)
            if not ok.any():
                continue
            p_s = p_ref * ok.mean() / st.mass
            w = np.exp(st.log_density_z(z_hits[ok]) - run.stage.proposal.log_q(z_hits[ok]))
            var += st.mass**2 * max(p_s * w.mean() - p_s**2, 0.0) / run.stage.n
            missed += ok.mean() * float((w > 100 * p_s).mean())
        rows.append((res.probability / p_ref, res.cov, math.sqrt(var) / p_ref, missed,
                     counted.n))
    a = np.array(rows)
    in2 = float(np.mean(np.abs(a[:, 0] - 1) <= 2 * a[:, 1] * a[:, 0]))
    print(f"  mean / reference {a[:, 0].mean():.3f}, spread {a[:, 0].std(ddof=1):.3f}, "
          f"reported CoV {a[:, 1].mean():.3f}, expected CoV "
          f"{math.sqrt(float(np.mean(a[:, 2] ** 2))):.3f}, mass where p/q > 100 P "
          f"{a[:, 3].mean():.3f}, in 2 CoV {in2:.2f}, evaluations {a[:, 4].mean():,.0f} "
          f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
