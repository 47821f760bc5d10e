"""Benchmark of the catalogue exports: time to export N scenarios in each format.

Builds N cut-ins (default 1,000) with ``sampler.scenario.builder.build_scenario`` from parameter
vectors drawn uniformly from a box of valid cut-ins (seeded), then exports the same items
in every format and mode, one after another, each into a fresh temporary directory:
``jsonl``, ``csv``, ``parquet``, ``xosc`` (``test`` and ``replay``; both include the
logical scenario) and ``commonroad``. Prints seconds, ms per scenario, the file size and
the ratio to the CSV export measured in the same run (the baseline: a flat row per
scenario), and the machine load (``uptime``) before and after.

    .venv/bin/python benchmarks/bench_exports.py            # 1,000 scenarios
    .venv/bin/python benchmarks/bench_exports.py --n 200    # quick
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.exports import build_manifest, export_catalogue  # noqa: E402
from riskcore.scenario import ConcreteScenario  # noqa: E402
from sampler.errors import BuilderError  # noqa: E402
from sampler.scenario.builder import build_scenario  # noqa: E402

#: (low, high) of each parameter; p_y1's sign is drawn separately
BOX = {"p_y1": (0.04, 0.09), "p_t": (1.5, 2.5), "p_a1": (-1.0, 1.0), "p_a2": (-1.0, 1.0),
       "p_a3": (0.0, 2.0), "p_v0": (20.0, 35.0), "dv": (-2.0, 6.0), "gap": (2.0, 30.0)}
RUNS: list[tuple[str, str, dict[str, Any]]] = [
    ("csv", "csv", {}),
    ("jsonl", "jsonl", {}),
    ("parquet", "parquet", {}),
    ("xosc test", "xosc", {"mode": "test"}),
    ("xosc replay", "xosc", {"mode": "replay"}),
    ("commonroad", "commonroad", {}),
]


def scenarios(n: int, seed: int) -> list[ConcreteScenario]:
    rng = np.random.default_rng(seed)
    out: list[ConcreteScenario] = []
    while len(out) < n:
        p = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in BOX.items()}
        p["p_y1"] *= 1.0 if rng.random() < 0.5 else -1.0
        try:
            out.append(build_scenario(p, seed=seed))
        except BuilderError:
            continue
    return out


def uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="scenarios (default 1000)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(f"load before: {uptime()}")
    t0 = time.perf_counter()
    items = [(s, {"exposure_weight": 1.0}) for s in scenarios(args.n, args.seed)]
    print(f"built {len(items)} scenarios in {time.perf_counter() - t0:.2f} s "
          f"(median {int(np.median([s.t.shape[0] for s, _ in items]))} steps)")
    manifest = build_manifest(seed=args.seed, model_hash=None, sampler_settings={},
                              constraints=[], p_region=None)
    baseline = None
    print(f"{'format':<12} {'s':>8} {'ms/scen':>8} {'MB':>8} {'x csv':>7}")
    for label, fmt, kwargs in RUNS:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / f"catalogue.{fmt}"
            start = time.perf_counter()
            export_catalogue(fmt, iter(items), manifest, out, **kwargs)
            seconds = time.perf_counter() - start
            size = out.stat().st_size / 1e6
        baseline = baseline or seconds
        print(f"{label:<12} {seconds:8.2f} {1e3 * seconds / len(items):8.2f} {size:8.2f} "
              f"{seconds / baseline:7.1f}")
    print(f"load after: {uptime()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
