"""``scengen data ...``: convert, extract, synthesise, fit surfaces, describe.

See app/cli.py for the conventions: user errors are ValueError/OSError, printed as one
line with exit code 2. Long work shows a progress bar on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

#: repository root (this file is app/cli_data.py)
_REPO = Path(__file__).resolve().parent.parent
#: default TNO input, relative to the repository: ../shared/data/tno-cutin/cut-in.json
DEFAULT_TNO_INPUT = _REPO.parent / "shared" / "data" / "tno-cutin" / "cut-in.json"


def _convert_tno(args: argparse.Namespace) -> int:
    from datasets.embedded import DEFAULT_EVENTS_PATH
    from datasets.tno_package import write_tno_package

    out = Path(args.output) if args.output else DEFAULT_EVENTS_PATH
    conv = write_tno_package(Path(args.input), out, rate=args.rate)
    for event_id, reason in conv.rejected:
        print(f"left out {event_id}: {reason}", file=sys.stderr)
    n_kept = conv.frame["event_id"].nunique()
    print(f"{conv.n_scenarios} events read, {n_kept} kept, {len(conv.rejected)} left out "
          f"as implausible; wrote {out}")
    return 0


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``scengen data`` and its sub-commands."""
    data = subparsers.add_parser("data", help="data sets: convert, extract, synth, surfaces")
    sub = data.add_subparsers(dest="data_command", metavar="SUBCOMMAND")
    data.set_defaults(func=lambda _args: (data.print_help(sys.stderr), 2)[1])

    p = sub.add_parser("convert-tno", help="convert TNO's cut-in.json to the embedded data")
    p.add_argument("--input", default=str(DEFAULT_TNO_INPUT),
                   help="TNO cut-in.json (default: %(default)s)")
    p.add_argument("-o", "--output", default=None,
                   help="output .parquet or .csv[.gz] (default: the embedded data file); "
                        "LICENSE and PROVENANCE.md are written next to it")
    p.add_argument("--rate", type=float, default=10.0, help="sampling rate in Hz (default 10)")
    p.set_defaults(func=_convert_tno)
