"""``scengen data ...``: convert, extract, synthesise, fit surfaces, describe.

See app/cli/main.py for the conventions: user errors are ValueError/OSError, printed as one
line with exit code 2. Long work shows a progress bar on stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli.options import CliError, add_out, add_quiet


def _convert_tno(args: argparse.Namespace) -> int:
    from datasets import DEFAULT_EVENTS_PATH, write_tno_package

    out = Path(args.output)
    if out.resolve() == DEFAULT_EVENTS_PATH.resolve() and not args.replace_embedded:
        raise CliError(f"{out} is the packaged embedded data; add --replace-embedded to "
                         "overwrite it")
    conv = write_tno_package(Path(args.input), out, rate=args.rate)
    for event_id, reason in conv.rejected:
        print(f"left out {event_id}: {reason}", file=sys.stderr)
    n_kept = conv.frame["event_id"].nunique()
    print(f"{conv.n_scenarios} events read, {n_kept} kept, {len(conv.rejected)} left out "
          f"as implausible; wrote {out}")
    return 0


def _extract(args: argparse.Namespace) -> int:
    from datasets import extract_cutins, write_table

    res = extract_cutins(args.path, args.format, progress=not args.quiet)
    for event_id, reason in res.skipped:
        print(f"skipped {event_id}: {reason}", file=sys.stderr)
    write_table(res.table, args.output)
    print(f"{len(res.table)} cut-ins extracted, {len(res.skipped)} skipped; "
          f"wrote {args.output}")
    if res.exposure is not None:  # highD: 'scengen fit TABLE' reads it from beside the table
        from sampler.rates import highd_exposure

        exp = highd_exposure(res.exposure, len(res.table))
        side = exposure_path(args.output)
        side.write_text(json.dumps(exp.to_dict(), indent=1) + "\n", encoding="utf-8")
        print(f"exposure: {exp.hours:.4g} vehicle-hours, {exp.km:.4g} vehicle-km; wrote {side}")
    return 0


def exposure_path(table: str | Path) -> Path:
    """Where a table's exposure is kept: ``TABLE.exposure.json`` beside it."""
    p = Path(table)
    return p.with_name(p.name + ".exposure.json")


def _synth(args: argparse.Namespace) -> int:
    from datasets import write_synthetic

    paths = write_synthetic(args.output, args.seed, minutes=args.minutes,
                            vehicles=args.vehicles, lanes_per_direction=args.lanes,
                            name=args.name)
    print(f"SYNTHETIC recording {args.name} (seed {args.seed}) written:")
    for p in paths:
        print(f"  {p}")
    return 0


def _fit_surfaces(args: argparse.Namespace) -> int:
    import pandas as pd

    from datasets import (
        fit_surfaces,
        trajectories_from_egocentric,
        trajectories_from_highd,
        write_surfaces,
    )

    if args.input is None:
        from datasets import EMBEDDED_SOURCE as SOURCE
        from datasets import load_default_events

        traj = trajectories_from_egocentric(load_default_events())
        source = f"embedded {SOURCE}"
    elif args.format == "egocentric":
        from datasets import read_egocentric

        traj = trajectories_from_egocentric(read_egocentric(args.input))
        source = str(args.input)
    else:
        from datasets import find_recordings, read_highd

        parts = []
        for prefix in find_recordings(args.input):
            rec = read_highd(prefix, progress=True)
            tr = trajectories_from_highd(rec)
            tr["track_id"] = prefix.name + "/" + tr["track_id"]
            parts.append(tr)
        traj = pd.concat(parts, ignore_index=True)
        source = f"highD format: {args.input}"
    surfaces = fit_surfaces(traj, source=args.source or source)
    write_surfaces(surfaces, args.output)
    print(f"input surfaces fitted from {source}; wrote {args.output}")
    return 0


def _scenarios(args: argparse.Namespace) -> int:
    import json
    import re

    from datasets import egocentric_to_scenarios, read_egocentric

    if args.events is None:
        from datasets import EMBEDDED_SOURCE as SOURCE
        from datasets import load_default_events

        frame, label = load_default_events(), f"embedded events ({SOURCE})"
    else:
        frame, label = read_egocentric(args.events), str(args.events)
    scenarios = egocentric_to_scenarios(frame)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    names: set[str] = set()
    for event_id, scenario in scenarios.items():
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", event_id) or "event"
        while name in names:  # ids that differ only in replaced characters
            name += "_"
        names.add(name)
        (out / f"{name}.json").write_text(json.dumps(scenario.to_dict()) + "\n",
                                          encoding="utf-8")
    print(f"{len(scenarios)} recorded events of {label} written as concrete scenarios to "
          f"{out}/ (score one: scengen risk {out}/<event>.json --summary)")
    return 0


def _describe(args: argparse.Namespace) -> int:
    import pandas as pd

    from datasets import describe_table, read_table

    if args.table is None:
        from datasets import EMBEDDED_SOURCE as SOURCE
        from datasets import default_parameter_table

        table = default_parameter_table()
        label = f"embedded table ({SOURCE})"
    else:
        table = read_table(args.table)
        label = str(args.table)
    print(f"{label}: {len(table)} cut-ins")
    with pd.option_context("display.width", 200, "display.max_columns", 20,
                           "display.float_format", "{:.4g}".format):
        print(describe_table(table).to_string())
    return 0


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``scengen data`` and its sub-commands."""
    data = subparsers.add_parser("data", help="data sets: convert, extract, synth, surfaces")
    sub = data.add_subparsers(dest="data_command", metavar="SUBCOMMAND")

    def _help(_args: argparse.Namespace) -> int:
        data.print_help(sys.stderr)
        return 2

    data.set_defaults(func=_help)

    p = sub.add_parser("convert-tno", help="convert TNO's cut-in.json to the ego-centric "
                       "format (how the embedded data were made)")
    p.add_argument("--input", required=True, metavar="cut-in.json",
                   help="TNO's cut-in.json (public repository "
                   "ErwindeGelder/ScenarioRiskQuantification, MIT)")
    add_out(p, required=True, help="output .parquet or .csv[.gz]; LICENSE and "
            "PROVENANCE.md are written next to it")
    p.add_argument("--replace-embedded", action="store_true",
                   help="allow --out to be the packaged embedded data file")
    p.add_argument("--rate", type=float, default=10.0, help="sampling rate in Hz (default 10)")
    p.set_defaults(func=_convert_tno)

    p = sub.add_parser("extract", help="extract cut-ins into the parameter table")
    p.add_argument("--format", required=True, choices=["highd", "egocentric"],
                   help="format of PATH")
    p.add_argument("path", help="highD folder or file, or ego-centric .csv/.parquet")
    add_out(p, required=True, help="table file (.parquet or .csv)")
    add_quiet(p)
    p.set_defaults(func=_extract)

    p = sub.add_parser("synth", help="write a SYNTHETIC highD-format recording")
    add_out(p, required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, required=True, help="seed of the synthetic traffic")
    p.add_argument("--minutes", type=float, default=15.0, help="recording length (15)")
    p.add_argument("--vehicles", type=int, default=1000, help="number of vehicles (1000)")
    p.add_argument("--lanes", type=int, default=3, help="lanes per direction (2-4)")
    p.add_argument("--name", default="01", help="recording prefix (digits, default 01)")
    p.set_defaults(func=_synth)

    p = sub.add_parser("fit-surfaces", help="fit riskcore's input-distribution surfaces")
    p.add_argument("input", nargs="?", default=None,
                   help="trajectories (default: the embedded TNO events)")
    p.add_argument("--format", choices=["egocentric", "highd"], default="egocentric",
                   help="format of INPUT (egocentric)")
    add_out(p, required=True, help="surfaces JSON file")
    p.add_argument("--source", default="", help="text for the file's 'source' field")
    p.set_defaults(func=_fit_surfaces)

    p = sub.add_parser("scenarios", help="write recorded events as concrete scenarios "
                       "(JSON, for scengen risk and POST /risk)")
    p.add_argument("events", nargs="?", default=None,
                   help="ego-centric .csv/.parquet (default: the embedded TNO events)")
    add_out(p, required=True, help="folder for the <event_id>.json files", metavar="DIR")
    p.set_defaults(func=_scenarios)

    p = sub.add_parser("describe", help="summary statistics of a parameter table")
    p.add_argument("table", nargs="?", default=None,
                   help=".parquet or .csv table (default: the embedded table)")
    p.set_defaults(func=_describe)
