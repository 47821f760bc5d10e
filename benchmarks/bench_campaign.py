"""Campaign estimator vs naive Monte Carlo (issue 24 item 8; docs/evaluation.md).

Part A, a stand-in SUT whose runs cost nothing (``late_brake_runner``: a late careful
driver, reaction ``--reaction`` s after the crossing, then ``--decel`` m/s²), on the
embedded TNO model with its bootstrap replicates:

* naive Monte Carlo of P(collision | physical cut-in) with ``--naive`` model draws
  (default 10^7; ``--quick`` 10^6) — the reference;
* ``--seeds`` (30) campaigns with the stop rule (relative half-width 0.3, >= 10
  collisions): how often the reported 95 % interval covers the naive estimate, the mean
  estimate, SUT runs per campaign, and the runs naive Monte Carlo needs for the same
  standard error (``P (1 - P) / SE^2``) and for the same relative half-width;
* wall clock of a campaign against naive Monte Carlo's time for those runs.

Part B (``--sut acc|idm|...``, skipped with ``--no-sut``): the same campaign with a
built-in SUT of ``riskcore.sut`` in the closed-loop simulator (``--sut-param k=v``), the
simulator's runs per second, and naive Monte Carlo of ``--naive-sut`` runs with that SUT
(default 0: its cost at the measured runs/s is printed instead).

    .venv/bin/python benchmarks/bench_campaign.py [--quick] [--seeds 30] [--naive 1e7]
        [--sut acc --sut-param a_min=-3] [--sut-seeds 1] [--naive-sut 0]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import beta, norm

from datasets.embedded import default_parameter_table
from riskcore.sut import SimSettings, SystemUnderTest, make_sut
from sampler import CutInGMM
from sampler.campaign import Runner, evaluate, late_brake_runner, sut_runner
from sampler.model import bootstrap_fit
from sampler.rates import tno_exposure
from sampler.region import Region


def naive(model: CutInGMM, runner: Runner, n_draws: int, seed: int, block: int = 1 << 20,
          sim_block: int | None = None) -> tuple[int, int, float]:
    """(collisions, physical cut-ins, seconds) of plain model draws."""
    rng = np.random.default_rng(seed)
    region = Region.from_constraints((), lane_width=model.lane_width_).bind(model)
    hits = inside = 0
    t0 = time.perf_counter()
    done = 0
    while done < n_draws:
        b = min(block, n_draws - done)
        z = model.sample_z(b, rng)
        x = model.params_matrix(model.from_z(z))
        ok = region.in_bounds(x)
        xs = x[ok]
        seeds: NDArray[np.uint64] = np.asarray(
            rng.integers(0, 2**63, size=xs.shape[0], dtype=np.uint64))
        step = sim_block or max(xs.shape[0], 1)
        for i in range(0, xs.shape[0], step):
            hits += int(np.asarray(runner(xs[i:i + step], seeds[i:i + step]).collided).sum())
        inside += int(ok.sum())
        done += b
    return hits, inside, time.perf_counter() - t0


_NAIVE_JOB: tuple[Any, ...] = ()


def _naive_block(job: tuple[int, np.random.SeedSequence]) -> tuple[int, int]:
    model, runner, region, sim_block = _NAIVE_JOB
    b, ss = job
    rng = np.random.default_rng(ss)
    x = model.params_matrix(model.from_z(model.sample_z(b, rng)))
    ok = region.in_bounds(x)
    xs = x[ok]
    seeds: NDArray[np.uint64] = np.asarray(
        rng.integers(0, 2**63, size=xs.shape[0], dtype=np.uint64))
    hits = 0
    for i in range(0, xs.shape[0], sim_block):
        hits += int(np.asarray(runner(xs[i:i + sim_block], seeds[i:i + sim_block]).collided).sum())
    return hits, int(ok.sum())


def naive_blocks(model: CutInGMM, runner: Runner, n_draws: int, seed: int, workers: int = 1,
                 block: int = 1 << 16, sim_block: int = 1024) -> tuple[int, int, float]:
    """``naive`` in blocks of ``block`` draws, block i with the i-th child of
    ``SeedSequence(seed)``: the same figures for any number of ``workers`` (forked
    processes, each running whole blocks)."""
    global _NAIVE_JOB
    import multiprocessing as mp

    region = Region.from_constraints((), lane_width=model.lane_width_).bind(model)
    sizes = [block] * (n_draws // block) + ([n_draws % block] if n_draws % block else [])
    jobs = list(zip(sizes, np.random.SeedSequence(seed).spawn(len(sizes)), strict=True))
    _NAIVE_JOB = (model, runner, region, sim_block)
    t0 = time.perf_counter()
    if workers <= 1:
        out = [_naive_block(j) for j in jobs]
    else:
        with mp.get_context("fork").Pool(workers) as pool:
            out = pool.map(_naive_block, jobs, chunksize=1)
    return sum(h for h, _ in out), sum(n for _, n in out), time.perf_counter() - t0


def envelope_reference(model: CutInGMM, runner: Runner, reaction: float, decel: float,
                       n_draws: int, seed: int, dv_max: float = 20.0
                       ) -> tuple[float, float, float, float]:
    """P(C | B) of the late-braking stand-in without the campaign's machinery: C needs
    dv > 0 and gap < dv reaction + dv^2 / (2 decel) <= dv (reaction + dv_max / (2 decel))
    for dv <= dv_max, so C lies in the half-space envelope of ``ttc < reaction + dv_max /
    (2 decel)`` (``sampler.methods.find_envelope``, exact mass P(S)); exact draws of the
    model restricted to S give P(C and B | S) by counting, times P(S), over P(B) (plain
    draws). The mass with dv > dv_max is below 1e-9 of the model's. Returns (P, CI low,
    CI high, seconds)."""
    from sampler.methods import find_envelope

    t0 = time.perf_counter()
    lane = model.lane_width_
    c = reaction + dv_max / (2 * decel)
    hs = find_envelope(model, Region.from_constraints([f"ttc<{c}"], lane_width=lane))
    if hs is None:  # a ttc constraint always has one (sampler.methods.envelope)
        raise SystemExit(f"no half-space envelope of ttc<{c}")
    region = Region.from_constraints((), lane_width=lane).bind(model)
    rng = np.random.default_rng(seed)
    hits = 0
    done = 0
    while done < n_draws:
        b = min(1 << 18, n_draws - done)
        x = model.params_matrix(model.from_z(hs.sample_z(model, b, rng)))
        ok = region.in_bounds(x)
        hits += int(np.asarray(runner(x[ok], np.zeros(int(ok.sum()), dtype=np.uint64))
                               .collided).sum())
        done += b
    k_b, n_b = 0, 0
    for _ in range(8):
        x = model.params_matrix(model.from_z(model.sample_z(1 << 18, rng)))
        k_b += int(region.in_bounds(x).sum())
        n_b += 1 << 18
    p_b = k_b / n_b
    lo, hi = cp(hits, n_draws)
    scale = hs.mass / p_b
    return hits / n_draws * scale, lo * scale, hi * scale, time.perf_counter() - t0


def cp(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    a = 1 - conf
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


_CAMPAIGN_JOB: tuple[Any, ...] = ()


def _campaign(s: int) -> dict[str, Any]:
    model, runner, kw = _CAMPAIGN_JOB
    t0 = time.perf_counter()
    summ = evaluate(model, runner, seed=s, **kw).summary()
    summ["wall_s"] = time.perf_counter() - t0
    return summ


def campaigns(model: CutInGMM, runner: Runner, seeds: range, workers: int = 1,
              **kw: Any) -> list[dict[str, Any]]:
    """One campaign per seed; ``workers`` > 1: forked processes, each running whole
    campaigns (the same figures; each campaign's wall clock is then its own process's)."""
    global _CAMPAIGN_JOB
    import multiprocessing as mp

    # the model-level figures (P(B), each replicate's P_b(B)) and the proposal's fixed
    # parts are memoised on the model once: not part of a campaign's cost
    evaluate(model, runner, seed=10**6, n=1, batch_size=1).summary()
    if kw.get("adapt") == "ce":
        from sampler.campaign.proposal import build_proposal
        build_proposal(model, region=None, lane_width=model.lane_width_)
    _CAMPAIGN_JOB = (model, runner, kw)
    if workers > 1:
        with mp.get_context("fork").Pool(workers) as pool:
            res = pool.imap(_campaign, seeds, chunksize=1)
            return [_show(s, summ) for s, summ in zip(seeds, res, strict=True)]
    return [_show(s, _campaign(s)) for s in seeds]


def _show(s: int, summ: dict) -> dict:
    p = summ["p_collision"]
    print(f"  seed {s:3d}: P {p['estimate']:.3e} CI [{p['ci'][0]:.2e}, {p['ci'][1]:.2e}] "
          f"rhw {p['rhw']:.2f} sut runs {summ['sut_runs']:6d} collisions "
          f"{summ['collisions']:4d} accel {summ['acceleration'] or 0:8.0f} "
          f"{summ['wall_s']:6.1f} s ({summ['stop_reason']})", flush=True)
    return summ


def report(name: str, res: list[dict], p_ref: float | None, ref_ci: tuple[float, float],
           naive_s_per_run: float, rhw: float = 0.3) -> None:
    est = np.array([r["p_collision"]["estimate"] for r in res])
    runs = np.array([r["sut_runs"] for r in res], dtype=float)
    wall = np.array([r["wall_s"] for r in res])
    se = np.array([r["p_collision"]["se"] for r in res])
    p = float(est.mean())
    z = float(norm.ppf(0.975))
    need_se = p * (1 - p) / se ** 2  # naive runs for each campaign's standard error
    need_rhw = z * z * (1 - p) / (p * rhw * rhw)  # naive runs for the campaigns' rhw
    print(f"\n[{name}] {len(res)} campaign(s)")
    print(f"  mean estimate {p:.3e} (sd of estimates {est.std(ddof=1) if est.size > 1 else 0:.2e})"
          f"; mean reported rhw {np.mean([r['p_collision']['rhw'] for r in res]):.2f}")
    if p_ref is not None:
        cov = np.mean([r["p_collision"]["ci"][0] <= p_ref <= r["p_collision"]["ci"][1]
                       for r in res])
        print(f"  naive reference {p_ref:.3e} [{ref_ci[0]:.2e}, {ref_ci[1]:.2e}]; "
              f"coverage of the 95 % interval: {cov * 100:.0f} %; mean / naive "
              f"{p / p_ref:.3f}")
    if len(res) > 1:  # against the pooled mean of all campaigns (precise, not independent)
        cov_m = np.mean([r["p_collision"]["ci"][0] <= p <= r["p_collision"]["ci"][1]
                         for r in res])
        print(f"  coverage of the mean of the {len(res)} estimates ({p:.3e}, standard error "
              f"{est.std(ddof=1) / math.sqrt(est.size):.1e}): {cov_m * 100:.0f} %")
    print(f"  SUT runs per campaign: mean {runs.mean():.0f} (min {runs.min():.0f}, max "
          f"{runs.max():.0f}); wall {wall.mean():.1f} s")
    print(f"  naive runs for the same SE: {np.mean(need_se):.3e} -> "
          f"{np.mean(need_se / runs):.0f}x fewer SUT runs (acceleration reported: "
          f"{np.mean([r['acceleration'] for r in res]):.0f})")
    if est.size > 1:  # the estimates' actual spread, not what each campaign reported
        sd = float(est.std(ddof=1))
        print(f"  naive runs for the estimates' actual spread (sd {sd:.2e}): "
              f"{p * (1 - p) / sd ** 2:.3e} -> {p * (1 - p) / sd ** 2 / runs.mean():.0f}x "
              "fewer SUT runs")
    print(f"  naive runs for rhw {rhw:g} at P: {need_rhw:.3e} -> {need_rhw / runs.mean():.0f}x "
          "fewer SUT runs")
    naive_wall = need_rhw * naive_s_per_run
    print(f"  wall: naive {naive_wall:.0f} s ({naive_s_per_run * 1e6:.1f} us per run) vs "
          f"campaign {wall.mean():.1f} s -> {naive_wall / wall.mean():.0f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--naive", type=float, default=1e7)
    ap.add_argument("--envelope", type=float, default=2e6)
    ap.add_argument("--reaction", type=float, default=0.6)
    ap.add_argument("--decel", type=float, default=6.0)
    ap.add_argument("--sut", default="acc")
    ap.add_argument("--sut-param", action="append", default=[])
    ap.add_argument("--sut-seeds", type=int, default=1)
    ap.add_argument("--naive-sut", type=float, default=0)
    ap.add_argument("--naive-seed", type=int, default=777,
                    help="root seed of the SUT's naive Monte Carlo (777 and 778 made the "
                         "reference 102/8392146; another root gives an independent sample)")
    ap.add_argument("--sut-seed0", type=int, default=0,
                    help="first campaign seed (seeds --sut-seed0 .. + --sut-seeds - 1)")
    ap.add_argument("--save", default=None, metavar="FILE",
                    help="write each SUT campaign's summary as a JSON line (coverage "
                         "against another reference can be recomputed from it)")
    ap.add_argument("--ref", default=None, metavar="HITS/RUNS",
                    help="a larger naive reference of the SUT measured earlier (e.g. "
                         "364/27992106 for acc k2=0.6 on 3.5 m lanes, docs/evaluation.md): "
                         "coverage is also reported against it")
    ap.add_argument("--sut-workers", type=int, default=1,
                    help="processes for the SUT campaigns (whole campaigns each)")
    ap.add_argument("--naive-workers", type=int, default=1,
                    help="processes for the SUT's naive Monte Carlo (blocks of 2^16 draws "
                         "with their own seeds: the same figures for any number)")
    ap.add_argument("--no-sut", action="store_true")
    ap.add_argument("--no-standin", action="store_true")
    ap.add_argument("--batch", type=int, default=2000)
    ap.add_argument("--sut-batch", type=int, default=500,
                    help="chunk size of the SUT campaigns (Part B)")
    ap.add_argument("--sut-rhw", type=float, default=0.3,
                    help="the SUT campaigns' stop rule: relative half-width of the 95 %% "
                         "interval (Part B)")
    ap.add_argument("--band-step", action="store_true",
                    help="SUT campaigns with evaluate(..., band_step=True)")
    ap.add_argument("--roulette", type=float, default=None,
                    help="SUT campaigns with evaluate(..., roulette=K) (default: "
                         "evaluate()'s own)")
    ap.add_argument("--alpha", type=float, default=None,
                    help="SUT campaigns with evaluate(..., alpha=A): the model's defensive "
                         "share (default: evaluate()'s own)")
    ap.add_argument("--final-alpha", type=float, default=None,
                    help="SUT campaigns with evaluate(..., final_alpha=A): the model's share "
                         "in the final stage only (the CLI and the API run 0.05 with the "
                         "roulette on; default: evaluate()'s own, alpha)")
    ap.add_argument("--tune-shares", action="store_true",
                    help="SUT campaigns with evaluate(..., tune_shares=True)")
    ap.add_argument("--adapt", default="ce", choices=("ce", "kernels"),
                    help="proposal adaptation of the SUT campaigns (Part B)")
    a = ap.parse_args()
    if a.quick:
        a.seeds, a.naive = min(a.seeds, 10), min(a.naive, 1e6)
        a.envelope = min(a.envelope, 2e5)
    t0 = time.perf_counter()
    table = default_parameter_table()
    model = CutInGMM().fit(table)
    bootstrap_fit(model, table, n_boot=100, seed=0)
    model.exposure_ = tno_exposure(table.shape[0]).to_dict()
    print(f"model: embedded TNO, K={model.n_components_}, 100 bootstrap replicates "
          f"({time.perf_counter() - t0:.0f} s)")

    if not a.no_standin:
        runner = late_brake_runner(a.reaction, a.decel)
        print(f"\nA. stand-in: late careful driver, reaction {a.reaction} s after the "
              f"crossing, {a.decel} m/s^2")
        k, n_in, secs = naive(model, runner, int(a.naive), seed=12345)
        lo, hi = cp(k, n_in)
        print(f"  naive: {int(a.naive):.2e} draws, {n_in} physical cut-ins, {k} collisions "
              f"-> P {k / n_in:.3e} [{lo:.2e}, {hi:.2e}] ({secs:.0f} s, "
              f"{secs / n_in * 1e6:.2f} us per run)")
        p_env, e_lo, e_hi, e_s = envelope_reference(model, runner, a.reaction, a.decel,
                                                    int(a.envelope), seed=54321)
        print(f"  reference by exact envelope draws ({int(a.envelope):.1e}): P {p_env:.3e} "
              f"[{e_lo:.2e}, {e_hi:.2e}] ({e_s:.0f} s); inside the naive interval: "
              f"{lo <= p_env <= hi}")
        res = campaigns(model, runner, range(a.seeds), batch_size=a.batch)
        report("stand-in vs naive", res, k / n_in, (lo, hi), secs / n_in)
        report("stand-in vs envelope reference", res, p_env, (e_lo, e_hi), secs / n_in)

    if not a.no_sut:
        params = {kv.split("=")[0]: float(kv.split("=")[1]) for kv in a.sut_param}
        settings = SimSettings(t_max=40.0)
        print(f"\nB. riskcore.sut '{a.sut}' {params} in the closed-loop simulator "
              f"(t_max {settings.t_max} s)")

        def factory() -> SystemUnderTest:
            return make_sut(a.sut, **params)

        # the lane width of the model's data, as evaluate() gives a runner without one: the
        # naive loop calls the runner directly, and a runner without a lane width builds
        # its cut-ins on 3.75 m lanes (the embedded TNO model's is 3.5 m). Until
        # 2026-11-27 (session 7) the naive references here were of 3.75 m lanes while the
        # campaigns ran on 3.5 m: about 5-10 % apart at k2=0.6 (docs/evaluation.md).
        runner_s = sut_runner(factory, careful=False, settings=settings, name=a.sut,
                              lane_width=model.lane_width_)
        print(f"  lane width {model.lane_width_:g} m (the model's)")
        print(f"  campaigns: adapt={a.adapt}, chunks of {a.sut_batch} runs")
        seeds = range(a.sut_seed0, a.sut_seed0 + a.sut_seeds)
        res = campaigns(model, runner_s, seeds, workers=a.sut_workers,
                        batch_size=a.sut_batch, adapt=a.adapt, rhw=a.sut_rhw,
                        **({"band_step": True} if a.band_step else {}),
                        **({"roulette": a.roulette} if a.roulette is not None else {}),
                        **({"alpha": a.alpha} if a.alpha is not None else {}),
                        **({"final_alpha": a.final_alpha} if a.final_alpha is not None
                           else {}),
                        **({"tune_shares": True} if a.tune_shares else {})) if seeds else []
        if a.save:
            with open(a.save, "w") as fh:
                for s, r in zip(seeds, res, strict=True):
                    fh.write(json.dumps({"seed": s, **r}, default=float) + "\n")
        if not res:  # naive Monte Carlo only
            if a.naive_sut > 0:
                k, n_in, secs_n = naive_blocks(model, runner_s, int(a.naive_sut),
                                               seed=a.naive_seed, workers=a.naive_workers)
                lo, hi = cp(k, n_in)
                print(f"  naive (seed {a.naive_seed}): {n_in} runs, {k} collisions -> P "
                      f"{k / n_in:.3e} [{lo:.2e}, {hi:.2e}] ({secs_n:.0f} s with "
                      f"{a.naive_workers} process(es), {n_in / secs_n:.0f} runs/s)")
            return
        parts = sorted({re.sub(r"(@.*|x\d+$)", "", p["part"]) for r in res
                        for p in r["proposal"]})
        print(f"  proposal parts of the final chunks: {', '.join(parts)}; pilot runs per "
              f"campaign: mean {np.mean([r['pilot_runs'] for r in res]):.0f}")
        runs = sum(r["sut_runs"] for r in res)
        secs = sum(r["wall_s"] for r in res)
        per_run = secs / runs
        print(f"  campaign throughput incl. proposal and weights: {runs / secs:.0f} runs/s")
        p_ref = None
        ci = (math.nan, math.nan)
        if a.naive_sut > 0:
            # runner calls of 1024 rows: 512-4096 run equally fast, 128 and 16384 slower
            # (bench_sut.py --only-runner --runner-blocks 128 512 1024 2048 4096 16384)
            k, n_in, secs_n = naive_blocks(model, runner_s, int(a.naive_sut), seed=a.naive_seed,
                                           workers=a.naive_workers)
            p_ref = k / n_in if k else None
            ci = cp(k, n_in)
            per_run = secs_n * a.naive_workers / n_in  # per core
            print(f"  naive: {n_in} runs, {k} collisions -> P {k / n_in:.3e} [{ci[0]:.2e}, "
                  f"{ci[1]:.2e}] ({secs_n:.0f} s with {a.naive_workers} process(es), "
                  f"{n_in / secs_n:.0f} runs/s)", flush=True)
        report(a.sut, res, p_ref, ci, per_run, a.sut_rhw)
        if a.ref:
            k_r, n_r = (int(v) for v in a.ref.split("/"))
            report(f"{a.sut} vs the given reference {a.ref}", res, k_r / n_r, cp(k_r, n_r),
                   per_run, a.sut_rhw)


if __name__ == "__main__":
    main()
