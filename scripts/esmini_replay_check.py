"""Replay a random catalogue in esmini in both modes and through the parameter distribution.

A larger version of tests/app/test_exports_esmini.py for the closing figures: N cut-ins
drawn as in benchmarks/bench_exports.py (seeded), exported in ``replay`` and ``test`` mode,
each file run by esmini (``$SCENGEN_ESMINI`` or ../shared/tools/esmini/bin/esmini, default
options, 0.05 s steps), and every permutation of the logical scenario. Prints the worst box
and heading errors against scengen, the collision-onset agreement (within one 0.1 s step),
test == replay, and permutation == per-scenario file.

    PYTHONPATH=. .venv/bin/python scripts/esmini_replay_check.py --n 200 --seed 11
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_exports import scenarios  # noqa: E402

from app.exports import build_manifest, export_catalogue  # noqa: E402
from tests.app import test_exports_esmini as T  # noqa: E402
from tests.app.esmini_run import EntityLog, esmini_binary, run_esmini  # noqa: E402


def _same(a: dict[str, EntityLog], b: dict[str, EntityLog]) -> bool:
    return all(a[k].t == b[k].t and all(np.max(np.abs(x - y)) <= T.CSV_TOL
                                        for x, y in zip(a[k].centres(), b[k].centres(),
                                                        strict=True))
               for k in ("ego", "cutter"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    binary = esmini_binary()
    if binary is None:
        print("esmini not found: set SCENGEN_ESMINI", file=sys.stderr)
        return 2
    sc = scenarios(args.n, args.seed)
    manifest = build_manifest(seed=args.seed, model_hash=None, sampler_settings={},
                              constraints=[], p_region=None)
    logs: dict[tuple[str, int], dict[str, EntityLog]] = {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for mode in ("replay", "test"):
            path = export_catalogue("xosc", [(s, {}) for s in sc], manifest,
                                    tmp / f"{mode}.zip", mode=mode)
            folder = tmp / mode
            with zipfile.ZipFile(path) as zf:
                zf.extractall(folder)
            box = heading = 0.0
            agree = collisions = 0
            for i, s in enumerate(sc):
                run = run_esmini(binary, folder / f"scenario_{i:07d}.xosc",
                                 folder / f"{i}.csv", step=T.STEP)
                logs[(mode, i)] = run
                t = s.t - s.t[0]
                for track in (s.ego, *s.objects):
                    b, h, _ = T._errors(track, t, run[track.id])
                    box, heading = max(box, b), max(heading, h)
                ours, theirs = T._scengen_collision(s), T._esmini_collision(run["ego"])
                collisions += ours is not None
                agree += (ours is None and theirs is None) or (
                    ours is not None and theirs is not None and abs(ours - theirs) <= T.DT + 1e-9)
            print(f"{mode}: {args.n} scenarios, max box error {box:.2e} m, max heading error "
                  f"{heading:.2e} rad, {collisions} collisions, onset within one step "
                  f"{agree}/{args.n}")
            if mode == "test":
                same = sum(_same(run_esmini(
                    binary, folder / "cutin_logical.xosc", folder / f"pd{i}.csv", step=T.STEP,
                    extra=("--param_dist", "cutin_distribution.xosc", "--param_permutation",
                           str(i))), logs[("test", i)]) for i in range(args.n))
                print(f"logical scenario: permutation == per-scenario test file {same}/{args.n}")
        same = sum(_same(logs[("replay", i)], logs[("test", i)]) for i in range(args.n))
        print(f"test (constant-speed ego) == replay: {same}/{args.n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
