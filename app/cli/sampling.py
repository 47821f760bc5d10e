"""``scengen fit`` and ``scengen sample``: the scenario model and constrained sampling.

``scengen fit [DATASET] -o MODEL.json`` fits the cut-in GMM (sampler.model.gmm.CutInGMM) to a
parameter table (CSV or Parquet as written by ``scengen data extract``; default: the
embedded real TNO table) and prints the BIC curve, the chosen K and the fit report.

``scengen sample [MODEL] -c 'ttc<3' -n 100 --seed 1 -o OUT.jsonl`` draws samples inside
the region (MODEL: a model JSON file written by ``scengen fit``, or a model id of the store;
default: the store's default model, fitted on the embedded data) and writes one JSON line
per sample::

    {"index": 0, "params": {...}, "ttc": ..., "exposure_weight": ..., "derived": {...},
     "log_density": ..., "scenario": {...} (with --scenarios),
     "risk": ..., "min_ttr": ..., ..., "error": ... (the score fields, with --score)}

i.e. the service's scored record (``sampler.scenario.record.ScenarioRecord``, the same as an item of
``POST /scenarios``) plus the sampler's derived quantities and log density; +inf/NaN are
written as "Infinity"/"NaN" (the service's JSON convention), and one summary line on
stderr with P(A), its interval and the sampler's diagnostics; ``--summary-json FILE``
writes the whole sample set without the per-sample arrays. User errors end as one line
``scengen: error: ...``, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli.data import exposure_path
from app.cli.options import (
    CliError,
    add_constraints,
    add_data_dir,
    add_n,
    add_out,
    add_quiet,
    add_sampler,
    store_label,
)

if TYPE_CHECKING:
    from sampler import CutInGMM

_SUFFIXES = (".csv", ".parquet", ".pq")
#: derived quantities a line carries in its record, not in "derived"
_IN_RECORD = frozenset({"support", "support_distance", "support_excess", "density_pct"})


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``scengen fit`` and ``scengen sample``."""
    f = subparsers.add_parser(
        "fit", help="fit the cut-in GMM to a parameter table",
        description="Fit the Gaussian-mixture scenario model (K by BIC) and write it as JSON.")
    f.add_argument("dataset", nargs="?", default=None, metavar="DATASET",
                   help="parameter table (.csv or .parquet); default: the embedded TNO data")
    add_out(f, required=True, metavar="MODEL.json", help="where to write the fitted model")
    f.add_argument("--k-min", type=int, default=1, help="fewest components tried (1)")
    f.add_argument("--k-max", type=int, default=8, help="most components tried (8)")
    f.add_argument("--n-init", type=int, default=5, help="EM restarts per K (5)")
    f.add_argument("--seed", type=int, default=0, help="random state (0)")
    f.add_argument("--features", default=None,
                   help="comma-separated table columns (default: the parameter vector)")
    f.add_argument("--lane-width", type=float, default=None,
                   help="lane width in m (default: the table's lane_width column, else 3.75)")
    f.add_argument("--bootstrap", type=int, default=100, metavar="B",
                   help="bootstrap refits stored for the model interval (100; 0: none)")
    f.add_argument("--bootstrap-jobs", type=int, default=1,
                   help="processes for the refits (1; 0: one per core)")
    f.add_argument("--exposure-hours", type=float, default=None,
                   help="hours of driving the table's cut-ins come from (embedded: 63 h)")
    f.add_argument("--exposure-km", type=float, default=None,
                   help="km of driving the table's cut-ins come from")
    f.set_defaults(func=_fit)

    s = subparsers.add_parser(
        "sample", help="sample cut-ins inside a region (rejection / MCMC)",
        description="Draw samples of the model restricted to the constraints and the "
                    "physical bounds; one JSON line per sample.")
    s.add_argument("model", nargs="?", default=None, metavar="MODEL",
                   help="model JSON file (scengen fit) or a model id of the store "
                   "(default: the store's default model)")
    s.add_argument("--model", dest="model_option", default=None, metavar="MODEL",
                   help="the same as the positional MODEL (as in 'catalogue create')")
    add_constraints(s, default_text="none: the whole model")
    add_n(s, default=100, what="samples")
    s.add_argument("--seed", type=int, default=None, help="seed (default: fresh, reported)")
    add_sampler(s)
    s.add_argument("--no-envelope", action="store_true",
                   help="draw from the whole model, not the region's half-space envelope")
    s.add_argument("--lane-width", type=float, default=None, help="lane width in m")
    s.add_argument("--score", action="store_true", help="build and score every scenario")
    s.add_argument("--wagner-scan", action="store_true",
                   help="with --score: also alarm_time, risk_peak and Wagner's risk at the "
                        "crossing (r_dep of the scripted ego at every step: about 2/3 of "
                        "the scoring time)")
    s.add_argument("--scenarios", action="store_true",
                   help="include each concrete scenario (JSON form) in its line")
    s.add_argument("--workers", type=int, default=1, help="processes for scoring (1)")
    s.add_argument("--budget", type=float, default=None, metavar="SECONDS",
                   help="stop a draw that would take longer, with a message (default: "
                        "SCENGEN_SYNC_BUDGET_SECONDS, 10 s, the service's budget for "
                        "POST /scenarios; 0: no limit)")
    add_out(s, required=False, default="-", metavar="OUT.jsonl",
            help="output file ('-' = stdout, the default)")
    s.add_argument("--summary-json", default=None, metavar="FILE",
                   help="write P(A), diagnostics and settings as JSON")
    add_quiet(s)
    add_data_dir(s)
    s.set_defaults(func=_sample)


def _read_table(path: str | None) -> tuple[Any, str]:
    import pandas as pd

    if path is None:
        from datasets import default_parameter_table

        return default_parameter_table(), "embedded TNO cut-ins (MIT)"
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _SUFFIXES:
        raise CliError(f"{path}: expected a parameter table .csv or .parquet")
    if not p.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        table = pd.read_csv(p) if suffix == ".csv" else pd.read_parquet(p)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise CliError(f"{path}: cannot read the table ({str(exc).splitlines()[0]})") from None
    return table, str(p)


def _fit(args: argparse.Namespace) -> int:
    from app.services import models as models_service
    from sampler.rates import Exposure, cutin_rate

    table, source = _read_table(args.dataset)
    if args.bootstrap < 0 or args.bootstrap == 1:
        raise CliError(f"--bootstrap: expected 0 or at least 2 refits, got {args.bootstrap}")
    options: dict[str, Any] = {"k_range": (args.k_min, args.k_max), "n_init": args.n_init,
                               "random_state": args.seed, "n_bootstrap": args.bootstrap}
    if args.features:
        options["features"] = [f.strip() for f in args.features.split(",") if f.strip()]
    if args.lane_width is not None:
        options["lane_width"] = args.lane_width
    exposure = None  # the embedded table's 63 h are the service's default
    if args.exposure_hours is not None or args.exposure_km is not None:
        exposure = Exposure(n_events=len(table), hours=args.exposure_hours,
                            km=args.exposure_km, source="given on the command line")
    elif args.dataset is not None and exposure_path(args.dataset).is_file():
        # written by 'scengen data extract' (highD)
        exposure = Exposure.from_dict({**json.loads(exposure_path(args.dataset).read_text(
            encoding="utf-8")), "n_events": len(table)})
    fitted = models_service.fit_model(table, options, source=source, exposure=exposure,
                                      bootstrap_jobs=args.bootstrap_jobs)
    model = fitted.model
    model.save(args.output)
    print(f"fitted {source}: {len(table)} rows")
    print(model.report_text())
    if args.bootstrap:
        print(f"bootstrap: {args.bootstrap} refits stored (model interval of P(A))")
    if model.exposure_ is not None:
        used = Exposure.from_dict(model.exposure_)
        rates = cutin_rate(used)
        print("exposure: " + "; ".join(
            f"{v['estimate']:.3g} cut-ins {k.replace('_', ' ').replace('1e6', '10^6')} "
            f"(95% {v['ci'][0]:.3g}-{v['ci'][1]:.3g})" for k, v in rates.items())
            + f" [{used.source}]")
    print(f"wrote {args.output}")
    return 0


def _clean(value: Any) -> Any:
    """JSON without inf/NaN (they become null)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


class StageBars:
    """tqdm bars on stderr, one per stage. A stage's ``total`` is its budget (the pilot's
    is its largest number of draws), which it may not use up: when the next stage starts,
    or at the end, a stage that stopped early says so ("16,384 (enough before the budget
    of 1,048,576)") instead of ending at 2 %.

    No rate is shown: a stage reports its count in jumps (the pilot's first report is
    16,384 draws a few microseconds after its bar appears), so tqdm's rate read
    "2454267026.29it/s"; and the total stays the budget (it jumped from 1,048,576 to
    16,384 at the end) (issue 25)."""

    #: the counts with thousands separators, written into the format (tqdm has none)
    RUNNING = "{{desc}}: {{percentage:3.0f}}%|{{bar}}| {n:,}/{total:,} [{{elapsed}}]"
    EARLY = "{{desc}}: {n:,} (enough before the budget of {total:,}) [{{elapsed}}]"

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bars: dict[str, Any] = {}
        self.current: str | None = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.quiet:
            return
        from tqdm import tqdm

        if stage != self.current:
            self._finish(self.current)
            self.current = stage
        bar = self.bars.get(stage)
        if bar is None:
            bar = self.bars[stage] = tqdm(
                total=total, initial=min(done, total), desc=stage, file=sys.stderr, leave=False,
                bar_format=self.RUNNING.format(n=min(done, total), total=total))
        bar.total = total
        bar.n = min(done, total)
        bar.bar_format = self.RUNNING.format(n=bar.n, total=total)
        bar.refresh()

    def _finish(self, stage: str | None) -> None:
        bar = self.bars.get(stage) if stage is not None else None
        if bar is not None and bar.n < (bar.total or 0):
            # the stage ended early: it needed no more
            bar.bar_format = self.EARLY.format(n=bar.n, total=bar.total)
            bar.refresh()

    def close(self) -> None:
        self._finish(self.current)
        self.current = None
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def _load_model(ref: str | None) -> CutInGMM:
    """A model file, a model id of the store, or (None / 'default') the default model."""
    from app.services import store
    from app.settings import get_settings

    try:
        return store.load_model(ref, get_settings(), field="--model")
    except LookupError as exc:
        raise LookupError(f"{exc.args[0] if exc.args else exc} in the store at "
                          f"{store_label()}") from None


def _budget_seconds(given: float | None) -> float:
    """``--budget`` (0: no limit), by default the service's synchronous budget."""
    if given is None:
        from app.settings import get_settings

        return float(get_settings().sync_budget_seconds)
    if not math.isfinite(given) or given < 0:
        raise CliError(f"--budget: seconds >= 0 (0: no limit), got {given:g}")
    return given


def _sample(args: argparse.Namespace) -> int:
    from app import budget, jsonconv
    from app.services import sampling as sampling_service
    from sampler.rates import region_report, report_text

    if args.workers < 1:
        raise CliError(f"--workers: must be >= 1, got {args.workers}")
    if args.model is not None and args.model_option is not None:
        raise CliError("give the model once: as MODEL or as --model")
    seconds = _budget_seconds(args.budget)
    model = _load_model(args.model if args.model is not None else args.model_option)
    progress = StageBars(args.quiet)
    try:
        with budget.limited(seconds, "scengen sample"):
            drawn = sampling_service.sample_local(
                model, args.constraints or [], args.n, args.seed, method=args.sampler,
                lane_width=args.lane_width, use_envelope=not args.no_envelope,
                progress=progress)
    except budget.OverBudget:
        raise CliError(
            f"this draw takes longer than the budget of {seconds:g} s (--budget, default "
            "SCENGEN_SYNC_BUDGET_SECONDS), so it was stopped; run it without the limit "
            "with --budget 0 (or a larger --budget), or narrow it (fewer samples, a less "
            "rare region)") from None
    finally:
        progress.close()
    ss = drawn.sample_set
    assert ss is not None  # domain.sample keeps the sampler's set
    records = sampling_service.score_on_pool(
        drawn, workers=args.workers, score=args.score, include_scenarios=args.scenarios,
        wagner_scan=args.wagner_scan,
        progress=(lambda d, t: progress("score", d, t)) if args.score else None)
    progress.close()
    d = ss.to_dict()
    lines = []
    for i, record in enumerate(records):
        row: dict[str, Any] = record.model_dump(exclude_none=not args.score)
        # the support quantities are in the record (with the class as a word)
        row["derived"] = {str(k): float(v) for k, v in ss.derived.iloc[i].items()
                          if k not in _IN_RECORD}
        row["log_density"] = d["log_density"][i]
        lines.append(jsonconv.dumps(row))
    text = "\n".join(lines) + "\n"
    if args.output == "-":
        sys.stdout.write(text)
    else:
        Path(args.output).write_text(text, encoding="utf-8")
    summary: dict[str, Any] = {}
    if args.summary_json:
        summary = {k: v for k, v in d.items()
                   if k not in ("params", "derived", "log_density", "exposure_weights")}
        Path(args.summary_json).write_text(json.dumps(_clean(summary), indent=1) + "\n",
                                           encoding="utf-8")
    print(f"scengen sample: seed {ss.seed}: {ss.summary()}", file=sys.stderr)
    if model.bootstrap_ or model.exposure_:
        report = region_report(model, ss)
        print(report_text(report), file=sys.stderr)
        if args.summary_json:
            summary["uncertainty"] = report
            Path(args.summary_json).write_text(json.dumps(_clean(summary), indent=1) + "\n",
                                               encoding="utf-8")
    return 0
