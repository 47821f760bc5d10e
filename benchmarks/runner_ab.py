"""The campaign's SUT runner of this checkout against another checkout's (a baseline
commit), measured in the same run: two worker processes, one per checkout, each running
``sampler.campaign.sut_runner`` (acc k2=0.5, careful=False, t_max 40 s) over the same
in-bounds model draws in blocks, passes alternating between them so that both see the
same machine state. Prints each side's rate (runs per second per core over the worker's
CPU time; best and median of the passes), the ratio, and a hash of every outcome field
of every row per side (equal hashes: bit-identical outcomes).

Usage (from the repository root; make the baseline with ``git worktree add --detach
/tmp/base <commit>``): ``PYTHONPATH=. .venv/bin/python benchmarks/runner_ab.py --base
/tmp/base [--passes 10] [--draws 16384] [--block 1024]``
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_PINNED = {v: "1" for v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                            "MKL_NUM_THREADS")}


def worker(draws: int, block: int, seed: int) -> None:
    """Read one line per pass from stdin, run the runner over the draws, print the CPU
    seconds; first print "ready <hash of the outcomes>"."""
    sys.path.insert(0, str(Path.cwd() / "benchmarks"))
    from bench_sut import runner_draws

    from riskcore.sut import SimSettings, make_sut
    from sampler.campaign import sut_runner

    x, seeds, _ = runner_draws(draws, seed)
    runner = sut_runner(lambda: make_sut("acc", k2=0.5), careful=False,
                        settings=SimSettings(t_max=40.0), lane_width=3.75, name="acc")
    starts = range(0, x.shape[0], block)
    h = hashlib.sha256()
    for i in starts:  # also compiles
        out = runner(x[i:i + block], seeds[i:i + block])
        for k in sorted(out.arrays):
            a = out.arrays[k]
            h.update(a.tobytes() if a.dtype.kind != "U" else repr(a.tolist()).encode())
    print("ready", x.shape[0], h.hexdigest()[:16], flush=True)
    for _ in sys.stdin:
        c = time.process_time()
        for i in starts:
            runner(x[i:i + block], seeds[i:i + block])
        print(time.process_time() - c, flush=True)


def _start(checkout: Path, args: argparse.Namespace) -> tuple[subprocess.Popen[str], int, str]:
    cmd = [sys.executable, str(ROOT / "benchmarks" / "runner_ab.py"), "--worker",
           "--draws", str(args.draws), "--block", str(args.block), "--seed", str(args.seed)]
    env = {**os.environ, **_PINNED, "PYTHONPATH": str(checkout)}
    p = subprocess.Popen(cmd, cwd=checkout, env=env, stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout is not None
    line = p.stdout.readline().split()
    if not line or line[0] != "ready":
        raise SystemExit(f"the worker in {checkout} did not start")
    return p, int(line[1]), line[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, help="the baseline checkout")
    ap.add_argument("--passes", type=int, default=10)
    ap.add_argument("--draws", type=int, default=16_384)
    ap.add_argument("--block", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.draws, args.block, args.seed)
        return
    if args.base is None or not (args.base / "sampler" / "campaign").is_dir():
        raise SystemExit("--base: a checkout of the repository (a baseline commit)")
    print(f"load average before: {os.getloadavg()[0]:.1f} (2-core machine shared)")
    sides = {"base": _start(args.base.resolve(), args), "this": _start(ROOT, args)}
    secs: dict[str, list[float]] = {k: [] for k in sides}
    for _ in range(args.passes):
        for name, (p, _, _) in sides.items():
            assert p.stdin is not None and p.stdout is not None
            p.stdin.write("go\n")
            p.stdin.flush()
            secs[name].append(float(p.stdout.readline()))
    for p, _, _ in sides.values():
        assert p.stdin is not None
        p.stdin.close()
        p.wait()
    for name, (_, n, digest) in sides.items():
        s = secs[name]
        best, median = n / min(s), n / statistics.median(s)
        print(f"  {name}: {best:9,.0f} runs/s per core best, {median:9,.0f} median of "
              f"{len(s)} passes; outcomes hash {digest}")
    b, t = secs["base"], secs["this"]
    same = sides["base"][2] == sides["this"][2]
    ratio = statistics.median(b) / statistics.median(t)
    print(f"  this / base: {min(b) / min(t):.2f}x best, {ratio:.2f}x median; outcomes "
          f"bit-identical: {same}")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
