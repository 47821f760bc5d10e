"""Benchmark: read and extract one full-size SYNTHETIC highD recording.

Generates (not timed) a recording of about 1,000 vehicles over 15 minutes with
``datasets.synth`` (seed 2024), writes the highD CSVs to a temporary folder, then times
``read_highd`` + ``extract_highd`` on one core. Prints tracks rows per second and seconds
per recording (target: <= 10 s). Figures measured on a shared machine are noisy.

Run: ``.venv/bin/python benchmarks/bench_datasets.py [--repeat N]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from datasets.extract import extract_highd_report
from datasets.highd import read_highd
from datasets.synth import write_synthetic


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (best is reported)")
    parser.add_argument("--seed", type=int, default=2024)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_synthetic(tmp, args.seed, minutes=15.0, vehicles=1000)
        gen = time.perf_counter() - t0
        prefix = Path(tmp) / "01"
        times_read, times_total = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            rec = read_highd(prefix)
            t1 = time.perf_counter()
            res = extract_highd_report(rec)
            t2 = time.perf_counter()
            times_read.append(t1 - t0)
            times_total.append(t2 - t0)
        rows = len(rec.tracks)
        best = float(np.min(times_total))
        size_mb = sum(p.stat().st_size for p in Path(tmp).glob("01_*.csv")) / 1e6
        print(f"SYNTHETIC recording: {len(rec.tracks_meta)} vehicles, {rows} track rows, "
              f"{size_mb:.1f} MB CSV, {len(res.table)} cut-ins extracted, "
              f"{len(res.skipped)} skipped (generation {gen:.1f} s, not timed)")
        print(f"read:            best {min(times_read):.2f} s of {args.repeat}")
        print(f"read + extract:  best {best:.2f} s, median {float(np.median(times_total)):.2f} s")
        print(f"rows per second: {rows / best:,.0f}")
        print(f"seconds per recording: {best:.2f} (target <= 10 s on one core)")


if __name__ == "__main__":
    main()
