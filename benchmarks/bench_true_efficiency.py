"""A campaign's true efficiency, measured with exact draws of the collision set.

A campaign's reported standard error comes from its own weights: a region of the
collision set C that its proposal q hardly covers shows up in them only when a run
happens to land there, with a weight p / q far above the rest. Until then the campaign
reports a small variance, and a benchmark of a few dozen campaigns reports a small
spread too: neither can see what no run has met.

This script measures the efficiency without that blind spot. Naive Monte Carlo gives
exact draws of ``p`` restricted to C (the collided runs of plain model draws); under a
proposal q, one run's second moment is ``E_q[(p/q)^2 1_C] = P E_{p|C}[p/q]``, so

    variance per run = P (E_{p|C}[w] - P),   w = p / q,
    runs saved over naive Monte Carlo = P (1 - P) / variance = (1 - P) / (E_{p|C}[w] - P)

and ``E_{p|C}[w]`` is the plain mean of ``p / q`` over the naive collisions: every
region of C counts with its true probability, met by a campaign or not. The script

* ``collect``: naive Monte Carlo of the SUT (blocks of 2^16 draws, block i from the
  i-th child of ``SeedSequence(seed)``, as ``bench_campaign.naive_blocks``), writing each
  collided draw's z row to a JSON-lines file, and the runs and collisions at its end;
* ``measure``: campaigns with the given seeds and stop rule, then for each the proposal
  its next chunk would draw from (rebuilt from its chunks, as the campaign builds it) and
  ``E_{p|C}[w]`` over the collected collisions, with a bootstrap interval over them, the
  runs saved per counted run and per SUT run (the pilot's runs included), the share of
  ``sum w`` in the ten heaviest collisions and, for those, the parameters and the parts
  of q that hold them.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_true_efficiency.py collect \\
        --sut acc --sut-param k2=0.6 --draws 3e7 --seed 2029 --out hits.jsonl
    PYTHONPATH=. .venv/bin/python benchmarks/bench_true_efficiency.py measure \\
        --sut acc --sut-param k2=0.6 --hits hits.jsonl --seeds 0-5 [--rhw 0.15]

docs/evaluation.md ("The campaigns' true efficiency") has the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from datasets import PARAM_NAMES
from datasets.embedded import default_parameter_table
from riskcore.sut import SimSettings, make_sut
from sampler import CutInGMM
from sampler.campaign import evaluate, next_ce_proposal, sut_runner
from sampler.campaign.evaluate import roulette_threshold
from sampler.campaign.proposal import DEFAULT_ENVELOPES
from sampler.model import bootstrap_fit
from sampler.rates import tno_exposure
from sampler.region import Region

FloatArray = NDArray[np.float64]


def efficiency(log_p: FloatArray, log_q: FloatArray, p_true: float, *, p_bounds: float = 1.0,
               n_boot: int = 2000, seed: int = 0) -> dict[str, float]:
    """From exact draws of p | C: ``E_{p|C}[p/q]``, the naive runs one draw of q saves,
    and a bootstrap 90 % interval of both (resampling the draws).

    ``p_true`` is P(C | B) and ``p_bounds`` P(B), B the physical cut-ins that naive Monte
    Carlo runs (the campaign's estimate is ``sum_i w_i 1_C(z_i) / (n P(B))`` over all its
    draws, ``p`` the model's density on all of z): one draw's variance is then
    ``P (E - P P(B)) / P(B)`` and a naive run's ``P (1 - P)``, so a draw saves
    ``(1 - P) P(B) / (E - P P(B))`` runs (``(1 - P) / (E - P)`` when B is everything).
    ``inf`` where ``E <= P P(B)`` (q at least as good as the zero-variance density on
    these draws)."""
    w = np.exp(np.asarray(log_p, dtype=np.float64) - np.asarray(log_q, dtype=np.float64))
    if w.size == 0:
        raise ValueError("efficiency: no collided draws")

    pc = p_true * p_bounds

    def saved(e: float) -> float:
        return (1.0 - p_true) * p_bounds / (e - pc) if e > pc else math.inf

    rng = np.random.default_rng(seed)
    boot = w[rng.integers(0, w.size, size=(n_boot, w.size))].mean(axis=1)
    lo, hi = np.quantile(boot, [0.05, 0.95])
    e = float(w.mean())
    return {"mean_w": e, "mean_w_lo": float(lo), "mean_w_hi": float(hi),
            "saved": saved(e), "saved_lo": saved(float(hi)), "saved_hi": saved(float(lo)),
            "top10_share": float(np.sort(w)[::-1][:10].sum() / w.sum())}


def _model() -> CutInGMM:
    table = default_parameter_table()
    model = CutInGMM().fit(table)
    bootstrap_fit(model, table, n_boot=100, seed=0)
    model.exposure_ = tno_exposure(table.shape[0]).to_dict()
    return model


def _runner(model: CutInGMM, sut: str, params: dict[str, float]) -> Any:
    # the model's lane width, as evaluate() gives the campaign's runner (bench_campaign)
    return sut_runner(lambda: make_sut(sut, **params), careful=False,
                      settings=SimSettings(t_max=40.0), name=sut,
                      lane_width=model.lane_width_)


_JOB: tuple[Any, ...] = ()


def _block(job: tuple[int, np.random.SeedSequence]) -> tuple[list[list[float]], int]:
    model, runner, region = _JOB
    b, ss = job
    rng = np.random.default_rng(ss)
    z = np.asarray(model.sample_z(b, rng), dtype=np.float64)
    x = model.params_matrix(model.from_z(z))
    ok = region.in_bounds(x)
    zs, xs = z[ok], x[ok]
    seeds = np.asarray(rng.integers(0, 2**63, size=xs.shape[0], dtype=np.uint64))
    out: list[list[float]] = []
    for i in range(0, xs.shape[0], 1024):
        hit = np.asarray(runner(xs[i:i + 1024], seeds[i:i + 1024]).collided, dtype=bool)
        out.extend(zs[i + r].tolist() for r in np.flatnonzero(hit))
    return out, int(ok.sum())


def collect(model: CutInGMM, runner: Any, draws: int, seed: int, out: str,
            workers: int) -> None:
    global _JOB
    region = Region.from_constraints((), lane_width=model.lane_width_).bind(model)
    block = 1 << 16
    sizes = [block] * (draws // block)
    jobs = list(zip(sizes, np.random.SeedSequence(seed).spawn(len(sizes)), strict=True))
    _JOB = (model, runner, region)
    t0 = time.perf_counter()
    hits = runs = 0
    with mp.get_context("fork").Pool(workers) as pool, open(out, "w") as fh:
        for k, (rows, m) in enumerate(pool.imap(_block, jobs, chunksize=1)):
            runs += m
            hits += len(rows)
            for r in rows:
                fh.write(json.dumps({"z": r}) + "\n")
            if k % 50 == 0 or k == len(jobs) - 1:
                print(f"  block {k + 1}/{len(jobs)}: {runs} runs, {hits} collisions "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
        fh.write(json.dumps({"runs": runs, "collisions": hits, "seed": seed,
                             "draws": draws}) + "\n")
    print(f"naive (seed {seed}): {hits} / {runs} = {hits / runs:.3e}")


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def read_hits(paths: Sequence[str]) -> tuple[FloatArray, int, int]:
    zs: list[list[float]] = []
    runs = hits = 0
    for path in paths:
        with open(path) as fh:
            for line in fh:
                row = json.loads(line)
                if "z" in row:
                    zs.append(row["z"])
                else:
                    runs += int(row["runs"])
                    hits += int(row["collisions"])
    return np.asarray(zs, dtype=np.float64), hits, runs


def measure(model: CutInGMM, runner: Any, paths: Sequence[str], seeds: Sequence[int],
            rhw: float, envelopes: Sequence[str], p_ref: float | None,
            max_runs: int = 1_000_000, band_step: bool = False,
            tune_shares: bool = False, roulette: float = 0.0) -> None:
    z, hits, runs = read_hits(paths)
    if hits != z.shape[0] or not runs:
        raise SystemExit(f"hits files: {z.shape[0]} rows but {hits} collisions recorded "
                         f"(a file without its closing line?)")
    p = p_ref if p_ref is not None else hits / runs
    print(f"{z.shape[0]} exact collisions from {runs} naive runs; P = {p:.3e}")
    log_p = np.asarray(model.log_density_z(z), dtype=np.float64)
    x = model.params_matrix(model.from_z(z))
    rows = []
    for s in seeds:
        t0 = time.perf_counter()
        res = evaluate(model, runner, seed=s, rhw=rhw, batch_size=500,
                       envelopes=tuple(envelopes), max_runs=max_runs, band_step=band_step,
                       tune_shares=tune_shares, roulette=roulette)
        summ = res.summary()
        pb = float(summ["p_bounds"])  # P(B) of the physical cut-ins
        prop = next_ce_proposal(res, envelopes=envelopes, band_step=band_step,
                                tune_shares=tune_shares)
        log_q = np.asarray(prop.log_q(z), dtype=np.float64)
        t = roulette_threshold(res.chunks, roulette)
        if t > 0:
            # with the roulette a collision run weighs max(w, t): the draws it kept are an
            # importance sample of q min(1, w / t); the runs it skipped are in sut_runs'
            # complement, so share_counted below counts them as not run
            log_q = np.minimum(log_q, log_p - math.log(t))
        eff = efficiency(log_p, log_q, p, p_bounds=pb)
        # naive runs saved per campaign SUT run (its pilot's runs included): the counted
        # draws each save eff["saved"], and the campaign ran sut_runs to make them
        share_counted = res.counted_runs / max(res.sut_runs, 1)
        est = summ["p_collision"]["estimate"]
        print(f"seed {s}: estimate {est:.3e} ({est / p:.2f} P), {res.sut_runs} SUT runs "
              f"({res.counted_runs} draws counted), stop {res.stop_reason}, reported "
              f"acceleration {summ.get('acceleration') or 0:.0f}; {time.perf_counter() - t0:.0f} s")
        print(f"  E_p|C[w] {eff['mean_w']:.2e} [{eff['mean_w_lo']:.2e}, "
              f"{eff['mean_w_hi']:.2e}] -> naive runs saved per counted draw {eff['saved']:.1f} "
              f"[{eff['saved_lo']:.1f}, {eff['saved_hi']:.1f}], per SUT run "
              f"{eff['saved'] * share_counted:.1f}; ten heaviest hold "
              f"{eff['top10_share'] * 100:.0f} % of sum w")
        w = np.exp(log_p - log_q)
        parts = np.stack([np.log(sh) + part.log_q(z)
                          for part, sh in zip(prop.parts, prop.shares, strict=True)])
        resp = np.exp(parts - logsumexp(parts, axis=0))
        names = [part.name for part in prop.parts]
        for i in np.argsort(-w)[:5]:
            top = np.argsort(-resp[:, i])[:2]
            held = ", ".join(f"{names[j]} {resp[j, i]:.2f}" for j in top)
            params = " ".join(f"{n}={v:.3g}" for n, v in zip(PARAM_NAMES, x[i], strict=True))
            print(f"    w {w[i]:.2e} ({held}): {params}")
        rows.append((eff["saved"], eff["saved"] * share_counted))
    a = np.asarray(rows)
    print(f"over {len(rows)} campaigns: naive runs saved per counted draw, median "
          f"{np.median(a[:, 0]):.1f} (range {a[:, 0].min():.1f} - {a[:, 0].max():.1f}); per "
          f"SUT run, median {np.median(a[:, 1]):.1f} (range {a[:, 1].min():.1f} - "
          f"{a[:, 1].max():.1f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mode", choices=("collect", "measure"))
    ap.add_argument("--sut", default="acc")
    ap.add_argument("--sut-param", action="append", default=[])
    ap.add_argument("--draws", type=float, default=3e7)
    ap.add_argument("--seed", type=int, default=2029)
    ap.add_argument("--out", default="hits.jsonl")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--hits", action="append", default=[])
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--rhw", type=float, default=0.15)
    ap.add_argument("--max-runs", type=int, default=1_000_000)
    ap.add_argument("--ref", type=float, default=None,
                    help="P from a larger naive reference (default: the hits files' own)")
    ap.add_argument("--extra-envelope", action="append", default=[],
                    help="a constraint added to the proposal's critical sets")
    ap.add_argument("--band-step", action="store_true",
                    help="campaigns with evaluate(..., band_step=True)")
    ap.add_argument("--tune-shares", action="store_true",
                    help="campaigns with evaluate(..., tune_shares=True)")
    ap.add_argument("--roulette", type=float, default=0.0,
                    help="campaigns with evaluate(..., roulette=K) (default 0: off)")
    a = ap.parse_args()
    params = {kv.split("=")[0]: float(kv.split("=")[1]) for kv in a.sut_param}
    model = _model()
    runner = _runner(model, a.sut, params)
    if a.mode == "collect":
        collect(model, runner, int(a.draws), a.seed, a.out, a.workers)
    else:
        measure(model, runner, a.hits, _seeds(a.seeds), a.rhw,
                (*DEFAULT_ENVELOPES, *a.extra_envelope), a.ref, a.max_runs, a.band_step,
                a.tune_shares, a.roulette)


if __name__ == "__main__":
    main()
