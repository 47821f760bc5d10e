"""The same systems under test on the same cut-ins in scengen's simulator and in esmini.

A ttc<3 catalogue of N cut-ins (the default model: ``CutInGMM(random_state=0)`` fitted on
the embedded TNO table, rejection sampling with ``--seed``) is driven by each built-in SUT
in scengen's closed-loop simulator (``riskcore.sut.simulate``) and in esmini
(``app.esmini.simulate_esmini``: the test-mode OpenSCENARIO export loaded by esmini's
library, the SUT asked every step), both with the default ``SimSettings`` (0.01 s steps).
Prints per SUT: collisions in each, collision verdicts that agree, the smallest gaps
within ``--gap-tol`` m (runs without contact in both; inf = inf), the largest differences
of smallest gap, impact speed and braking moment, how the esmini runs ended, the wall
clock of each simulator; then every run that differs, with the figures.

The library: ``--library``, else ``$SCENGEN_ESMINI_LIB``, else
../shared/tools/esmini/lib/libesminiLib.so next to the checkout.

    PYTHONPATH=. .venv/bin/python scripts/esmini_sut_agreement.py --n 200 --seed 7
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.esmini import ENV_VAR, esmini_world, simulate_esmini  # noqa: E402
from datasets import default_parameter_table  # noqa: E402
from riskcore.scenario import ConcreteScenario  # noqa: E402
from riskcore.sut import CutInBatch, RunBatch, SimSettings, make_sut, simulate  # noqa: E402
from sampler import CutInGMM, sample  # noqa: E402

SHARED_LIB = ROOT.parent / "shared" / "tools" / "esmini" / "lib" / "libesminiLib.so"


def catalogue(n: int, seed: int) -> list[ConcreteScenario]:
    """N ttc<3 cut-ins of the default model (rejection sampling, seeded)."""
    model = CutInGMM(random_state=0).fit(default_parameter_table())
    return list(sample(model, ["ttc<3"], n=n, seed=seed, method="rejection").scenarios())


def gaps_agree(a: np.ndarray, b: np.ndarray, tol: float) -> np.ndarray:
    """Per run: both infinite, or both finite and within tol."""
    both_inf = np.isinf(a) & np.isinf(b)
    with np.errstate(invalid="ignore"):
        return both_inf | (np.abs(a - b) <= tol)


@dataclass
class Agreement:
    """scengen's runs against esmini's for one SUT."""

    collisions: tuple[int, int]
    verdicts: int
    gaps: int
    no_contact: int
    ends: int
    dgap: float
    dimpact: float
    dbrake: float
    esmini_ends: Counter[str]


def compare(ours: RunBatch, theirs: RunBatch, tol: float, dt: float) -> Agreement:
    no_contact = ~ours.collided & ~theirs.collided
    both = ours.collided & theirs.collided
    finite = no_contact & np.isfinite(ours.min_gap) & np.isfinite(theirs.min_gap)
    dgap = np.abs(ours.min_gap - theirs.min_gap)
    dbrake = np.abs(ours.t_brake_rel_tp - theirs.t_brake_rel_tp)
    same_end = (ours.end == theirs.end) & (np.abs(ours.end_time - theirs.end_time) <= dt + 1e-9)
    return Agreement(
        collisions=(int(ours.collided.sum()), int(theirs.collided.sum())),
        verdicts=int((ours.collided == theirs.collided).sum()),
        gaps=int(gaps_agree(ours.min_gap, theirs.min_gap, tol)[no_contact].sum()),
        no_contact=int(no_contact.sum()), ends=int(same_end.sum()),
        dgap=float(dgap[finite].max(initial=0.0)),
        dimpact=float(np.abs(ours.impact_speed - theirs.impact_speed)[both].max(initial=0.0)),
        dbrake=float(np.nanmax(dbrake, initial=0.0)),
        esmini_ends=Counter(str(e) for e in theirs.end))


def world_gap(ours_world: RunBatch, theirs: RunBatch) -> float:
    """The largest difference of smallest gap and contact time between esmini's runs and
    scengen's on esmini's world (m or s; inf when a verdict differs)."""
    if np.any(ours_world.collided != theirs.collided):
        return math.inf
    d = [np.abs(ours_world.min_gap - theirs.min_gap), np.abs(ours_world.t_contact
                                                             - theirs.t_contact)]
    return float(max(np.nanmax(np.where(np.isinf(x), 0.0, x), initial=0.0) for x in d))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--suts", default="none,idm,acc,acc_aeb,r157_cc,r157_cc_conflict,rss")
    parser.add_argument("--gap-tol", type=float, default=0.1)
    parser.add_argument("--library", default=None)
    args = parser.parse_args()
    library = args.library or os.environ.get(ENV_VAR) or str(SHARED_LIB)
    if not Path(library).is_file():
        print(f"esmini library not found: set {ENV_VAR} or --library", file=sys.stderr)
        return 2
    t = time.perf_counter()
    scenarios = catalogue(args.n, args.seed)
    batch = CutInBatch.from_scenarios(scenarios)
    print(f"{len(scenarios)} ttc<3 cut-ins of the default model (seed {args.seed}), "
          f"built in {time.perf_counter() - t:.1f} s; esmini library {library}")
    simulate(make_sut("none"), batch.subset(slice(0, 2)), seeds=0)  # compile before timing
    head = (f"| SUT | runs | collisions scengen / esmini | verdicts agree | min gap within "
            f"{args.gap_tol} m | max |Δ gap| (m) | max |Δ impact| (m/s) | max |Δ brake| (s) "
            "| ends agree | esmini ends | scengen on esmini's world: max diff "
            "| s scengen / esmini |")
    print(head)
    print("|---" * 12 + "|")
    notes: list[str] = []
    for name in args.suts.split(","):
        t0 = time.perf_counter()
        ours = simulate(make_sut(name), batch, seeds=args.seed)
        t1 = time.perf_counter()
        res = simulate_esmini(make_sut(name), scenarios, seeds=args.seed, library=library,
                              profiles=True)
        t2 = time.perf_counter()
        theirs = res.runs
        assert theirs.profiles is not None
        world = simulate(make_sut(name), esmini_world(batch, theirs.profiles), seeds=args.seed)
        c = compare(ours, theirs, args.gap_tol, SimSettings().dt)
        n = len(scenarios)
        ends = ", ".join(f"{k} {v}" for k, v in sorted(c.esmini_ends.items()))
        print(f"| {name} | {n} | {c.collisions[0]} / {c.collisions[1]} | {c.verdicts}/{n} | "
              f"{c.gaps}/{c.no_contact} | {c.dgap:.4f} | {c.dimpact:.4f} | {c.dbrake:.4f} | "
              f"{c.ends}/{n} | {ends} | {world_gap(world, theirs):.1e} | "
              f"{t1 - t0:.2f} / {t2 - t1:.1f} |")
        drift = float(res.diagnostics.ego_drift.max())
        bad = int(res.diagnostics.flag_box_disagree.sum())
        notes.append(f"{name}: esmini's ego within {drift:.1e} m of the vehicle model; "
                     f"{bad} steps where esmini's collision flag and the box test disagree")
        ok = gaps_agree(ours.min_gap, theirs.min_gap, args.gap_tol)
        for i in np.flatnonzero((ours.collided != theirs.collided)
                                | (~ours.collided & ~theirs.collided & ~ok)):
            p = ", ".join(f"{k} {v:.4g}" for k, v in scenarios[i].params.items())
            notes.append(
                f"  {name} run {i}: collided {bool(ours.collided[i])} / "
                f"{bool(theirs.collided[i])}, impact {ours.impact_speed[i]:.3f} / "
                f"{theirs.impact_speed[i]:.3f} m/s, min gap {ours.min_gap[i]:.4f} / "
                f"{theirs.min_gap[i]:.4f} m, brake {ours.t_brake_rel_tp[i]:.4f} / "
                f"{theirs.t_brake_rel_tp[i]:.4f} s after t_p, end {ours.end[i]} "
                f"{ours.end_time[i]:.2f} / {theirs.end[i]} {theirs.end_time[i]:.2f} s ({p})")
    print()
    print("\n".join(notes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
