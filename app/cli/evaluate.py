"""``scengen evaluate``: a system under test driven through importance-sampled cut-ins
(issue 24; docs/evaluation.md).

``scengen evaluate --sut NAME [-c C]... [-n N | --rhw R] [--adapt ce|kernels] [--band-step]
[--roulette K] [--seed S] [--runs FILE]`` runs
a campaign in this process (``sampler.campaign.evaluate``; nothing is stored) and prints
its summary as JSON on stdout: ``p_collision`` and ``rate_per_hour`` (each ``estimate``,
``ci`` and the model interval ``model_ci``), ``runs``, ``collisions``, ``ess``,
``acceleration`` and the rest of ``CampaignResult.summary()``; a progress bar on stderr,
then each of the summary's ``warnings`` as one line ``warning: ...`` on stderr.
``--runs FILE`` writes every draw (parameters, weight, outcome; ``simulated`` false for
draws outside the region or the physical bounds, which were not run) as JSON lines.

NAME is a registered SUT (``--list-suts``: the built-ins and the installed packages'
entry points in the group ``scengen.suts``) or, on the command line only, a
``module:Object`` reference (a class of either SUT protocol, a factory, a SutSpec).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli.options import CliError, add_constraints, add_data_dir, add_quiet

#: the summary's keys printed first, in this order (the rest follow as the campaign gives)
FIRST_KEYS = ("sut", "p_collision", "rate_per_hour", "runs", "collisions", "ess",
              "acceleration")


#: the stop rule's relative half-width when neither -n nor --rhw is given:
#: ``sampler.campaign.DEFAULT_RHW`` (where it is explained), written out so that building
#: the parser and printing --help import no sampler (2 s); ``tests/app/
#: test_stop_rule_default.py`` checks that the two agree
DEFAULT_RHW = 0.15
#: ``--adapt``'s choices, the default first: ``app.services.evaluations.ADAPT`` and
#: ``sampler.campaign.evaluate(adapt=...)``'s default, written out for the same reason and
#: checked by the same test
ADAPT_CHOICES = ("ce", "kernels")


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``scengen evaluate``."""
    p = subparsers.add_parser(
        "evaluate", help="estimate a system under test's collision rate (importance "
        "sampling)", description="Drive a system under test through importance-sampled "
        "cut-ins of the model and print its collision probability per cut-in and rate per "
        "hour with both intervals, as JSON (docs/evaluation.md).")
    p.add_argument("--sut", default=None, metavar="NAME",
                   help="a registered SUT (see --list-suts) or module:Class")
    p.add_argument("--sut-param", action="append", default=[], metavar="KEY=VALUE",
                   dest="sut_params",
                   help="a parameter of the SUT (repeatable; VALUE as JSON, e.g. "
                   "time_gap=1.5)")
    p.add_argument("--setting", action="append", default=[], metavar="KEY=VALUE",
                   dest="settings", help="a simulator setting (riskcore.sut.SimSettings, "
                   "repeatable; e.g. perception_delay=0.2)")
    p.add_argument("--risk", action="store_true",
                   help="also compute Wagner's TTR risk of the SUT's own drive per run "
                   "(r_dep_peak, r_ind_peak, r_dep_time_above in --runs; costly)")
    p.add_argument("--list-suts", action="store_true",
                   help="print the registered SUTs as JSON and exit")
    add_constraints(p, default_text="none: the model's whole distribution")
    how = p.add_mutually_exclusive_group()
    how.add_argument("-n", "--n", dest="n", type=int, default=None, metavar="N",
                     help="exactly N draws (no stop rule)")
    how.add_argument("--rhw", type=float, default=None, metavar="R",
                     help="stop when the relative half-width of the 95 %% interval is at "
                     f"most R, with at least 10 collisions (default {DEFAULT_RHW})")
    p.add_argument("--max-runs", type=int, default=None, metavar="M",
                   help="most draws with the stop rule (200000)")
    p.add_argument("--adapt", choices=ADAPT_CHOICES, default=ADAPT_CHOICES[0],
                   help="how later chunks adapt the proposal: 'ce' (default: adaptive "
                   "cross-entropy on the SUT's performance score: pilot chunks until 20 "
                   "collided runs, then only the final stage counts) or 'kernels' "
                   "(Student-t kernels on the collisions so far, every run counts; at P "
                   "near 1e-5 its interval undercovers, docs/evaluation.md)")
    p.add_argument("--band-step", action="store_true",
                   help="with --adapt ce: the final stage's band step (each band part of "
                   "the proposal gets its own cross-entropy step, shares move to the "
                   "band parts); about 4.6x fewer runs on an ACC at P near 1e-5, 2.5x more "
                   "at P near 1e-3 (docs/evaluation.md)")
    p.add_argument("--roulette", type=float, default=None, metavar="K",
                   help="with --adapt ce: weight roulette's factor (default 5; 0: off): "
                   "in the final stage a draw whose weight is below K times the estimate "
                   "so far is run only with probability weight/threshold (unbiased), and "
                   "the final stage draws the model with share 0.05 instead of 0.15; "
                   "about 1.3x and then 1.2x fewer SUT runs at P near 1e-5 and 1e-3 "
                   "(docs/evaluation.md)")
    p.add_argument("--seed", type=int, default=0, help="campaign seed (0)")
    p.add_argument("--batch-size", type=int, default=None, metavar="B",
                   help="draws per chunk (2000)")
    p.add_argument("--model", default=None, metavar="MODEL",
                   help="model JSON file (scengen fit) or a model id of the store "
                   "(default: the store's default model)")
    p.add_argument("--workers", type=int, default=0, metavar="W",
                   help="processes that run the SUT (0: in this process, the default)")
    p.add_argument("--runs", default=None, metavar="FILE",
                   help="write every draw (parameters, weight, outcome) as JSON lines")
    add_quiet(p)
    add_data_dir(p)
    p.set_defaults(func=_evaluate)


def _pairs(items: list[str], option: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise CliError(f"{option}: expected KEY=VALUE, got {item!r}")
        try:
            value: Any = json.loads(raw)
        except json.JSONDecodeError:
            value = raw  # a bare word
        out[key.strip()] = value
    return out


class _Bar:
    """One tqdm bar of draws on stderr (its total: n, or max_runs with the stop rule).

    With the stop rule the bar shows no time remaining: the campaign usually stops long
    before max_runs, and an estimate to max_runs ("1:07:35" for a campaign that ended
    after 2.5 minutes) only alarmed."""

    def __init__(self, quiet: bool, stop_rule: str | None = None) -> None:
        self.quiet = quiet
        self.stop_rule = stop_rule
        self.bar: Any = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.quiet:
            return
        if self.bar is None:
            from tqdm import tqdm

            fmt = None if self.stop_rule is None else (
                "{desc}: {n_fmt} of at most {total_fmt} [{elapsed}, {rate_fmt}] until "
                + self.stop_rule)
            self.bar = tqdm(total=total, desc="draws", unit="run", file=sys.stderr,
                            leave=False, smoothing=0, bar_format=fmt)
        self.bar.n = min(done, total)
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _evaluate(args: argparse.Namespace) -> int:
    from app import jsonconv
    from app.cli.sampling import _load_model
    from app.services import evaluations as service
    from app.services import suts

    if args.list_suts:
        print(json.dumps([s.model_dump(mode="json") for s in suts.list_suts()], indent=1))
        return 0
    if args.sut is None:
        raise CliError("--sut: give the system under test (a registered name, see "
                         "--list-suts, or module:Class)")
    if args.workers < 0:
        raise CliError(f"--workers: must be >= 0, got {args.workers}")
    entry = suts.resolve(args.sut, allow_import=True, field="--sut")
    factory = suts.make_factory(entry, _pairs(args.sut_params, "--sut-param"),
                                field="--sut-param")
    roulette = service.default_roulette(args.adapt, args.roulette)
    spec = service.CampaignSpec(
        sut=entry.name, sut_params=dict(factory.params), constraints=args.constraints or [],
        n=args.n, rhw=DEFAULT_RHW if args.rhw is None else float(args.rhw),
        max_runs=service.DEFAULT_MAX_RUNS if args.max_runs is None else args.max_runs,
        seed=args.seed,
        # 0 is refused by check_spec, not taken for "the default"
        batch_size=service.DEFAULT_BATCH if args.batch_size is None else args.batch_size,
        settings=_pairs(args.settings, "--setting") or None, risk=bool(args.risk),
        adapt=args.adapt, band_step=bool(args.band_step),
        roulette=roulette, final_alpha=service.default_final_alpha(roulette))
    service.check_spec(spec, limit=10**9, where="")
    service.check_settings(spec.settings, "--setting")
    runner = service.runner_for(None, factory, spec.settings, spec.risk)
    model = _load_model(args.model)
    if args.runs is not None and not Path(args.runs).parent.is_dir():
        raise CliError(f"--runs: directory {str(Path(args.runs).parent)!r} does not exist")
    pool = None
    if args.workers > 0:
        from app.jobs.executors import LocalPoolExecutor

        pool = LocalPoolExecutor(args.workers)
    bar = _Bar(args.quiet, None if spec.n is not None else
               f"the 95 % interval is within ±{spec.rhw:g} (relative), 10 collisions at least")
    # the bar starts now, at 0 of the planned draws, so its rate is draws per second of
    # simulation (it advances after each chunk of --batch-size draws)
    bar("runs", 0, spec.planned)
    try:
        result = service.campaign(model, factory, spec, runner=runner, progress=bar,
                                  executor=None if pool is None else pool.futures_executor())
    finally:
        bar.close()
        if pool is not None:
            pool.close()
    summary: dict[str, Any] = result.summary()
    ordered = {k: summary[k] for k in FIRST_KEYS if k in summary}
    ordered.update({k: v for k, v in summary.items() if k not in ordered})
    if args.runs is not None:
        with open(args.runs, "w", encoding="utf-8") as fh:
            for rec in result.records():
                # a uint64 as a string, as GET /evaluations/{id}/runs gives it: jq 1.6 and
                # JavaScript round a number this large (17923096090236241182 read back as
                # ...242000), and the seed is what reproduces the run
                rec["seed"] = str(rec["seed"])
                fh.write(jsonconv.dumps(rec) + "\n")
    print(json.dumps(jsonconv.encode(ordered), indent=1))
    # the summary's verdict (sampler.campaign.reliability), also with -q: the exit code
    # stays 0, the JSON on stdout stays parseable
    for text in summary.get("warnings") or []:
        print(f"warning: {text}", file=sys.stderr)
    return 0
