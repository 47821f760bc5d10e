"""``scengen risk SCENARIO.json``: score a concrete scenario with riskcore, print JSON.

The input is the concrete-scenario JSON form (riskcore.scenario; docs/riskcore.md). The
output is the same report as ``POST /risk``: summary, per-step series and per-object series
(``--samples`` adds every object's per-sample Monte-Carlo arrays, ``--summary`` prints only
the summary); +inf is written as "Infinity" (the service's JSON convention). Settings of Table
II and the ego's capabilities can be overridden on the command line. User errors (missing
file, bad JSON, a malformed scenario, bad settings) end as one line
``scengen: error: ...`` naming the file and field, with exit code 2 (see app/cli/main.py).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli.options import CliError, add_out

#: command-line option → (RiskSettings field, type, help)
_SETTING_OPTIONS: tuple[tuple[str, str, type, str], ...] = (
    ("--horizon", "horizon", float, "prediction horizon in s (3.0)"),
    ("--dt", "dt", float, "prediction step in s (0.1)"),
    ("--n-a", "n_a", int, "acceleration grid points (10)"),
    ("--n-omega", "n_omega", int, "turn-rate grid points (10)"),
    ("--sigma-range", "sigma_range", float, "grid half-width in standard deviations (3.0)"),
    ("--t-pnr", "t_pnr", float, "point of no return T_PNR in s (0.5)"),
    ("--t-max", "t_max", float, "maximum risk time T_max in s (2.0)"),
    ("--m", "m", float, "steepness m of the TTR weighting (1.0)"),
    ("--brake-max", "brake_max", float, "ego full-braking deceleration in m/s^2 (8.0)"),
    ("--accel-max", "accel_max", float, "ego full acceleration in m/s^2 (2.0)"),
    ("--lat-accel-max", "lat_accel_max", float, "ego lateral-acceleration limit in m/s^2 (6.0)"),
    ("--min-turn-radius", "min_turn_radius", float, "ego smallest turning radius in m (5.5)"),
)


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``scengen risk``."""
    p = subparsers.add_parser(
        "risk", help="score a concrete scenario (Monte-Carlo time-to-react risk)",
        description="Read a concrete scenario (JSON) and print its risk per time step as "
                    "JSON: series, per object and step the TTR, weight and evasion arrays, and "
                    "its criticality record as a cut-in (class, btn, ttr_true, ...).")
    p.add_argument("scenario", metavar="SCENARIO.json", help="concrete scenario (JSON form)")
    p.add_argument("--pretty", action="store_true", help="indent the JSON output")
    add_out(p, required=False, default="-", help="output file ('-' = stdout, the default)")
    p.add_argument("--summary", action="store_true",
                   help="print only the flat summary (risk, min TTR, ...) and the "
                        "criticality record")
    p.add_argument("--samples", action="store_true",
                   help="include the per-sample Monte-Carlo arrays (large)")
    p.add_argument("--surfaces", metavar="FILE", default=None,
                   help="input-surfaces file (default: the packaged one)")
    for flag, dest, typ, text in _SETTING_OPTIONS:
        p.add_argument(flag, dest=dest, type=typ, default=None, help=text)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from app import jsonconv
    from app.errors import InvalidInput
    from app.services import risk
    from riskcore import InputSurfaces

    overrides = {dest: getattr(args, dest) for _, dest, _, _ in _SETTING_OPTIONS
                 if getattr(args, dest) is not None}
    settings = risk.risk_settings(overrides)
    surfaces = InputSurfaces.load(args.surfaces) if args.surfaces else None
    data = risk.read_scenario_file(args.scenario)
    try:
        report = risk.score(data, samples=args.samples, settings=settings, surfaces=surfaces)
    except InvalidInput as exc:  # name the file as well as the field
        raise CliError(f"{args.scenario}: {exc.message}") from None
    text = (jsonconv.dumps({**report.summary, "criticality": report.criticality})
            if args.summary else report.model_dump_json())
    if args.summary:  # a page to read (issue 25 item 6): one field a line, no float noise
        text = json.dumps(readable(json.loads(text)), indent=2)
    elif args.pretty:
        text = json.dumps(json.loads(text), indent=2)
    if args.output == "-":
        sys.stdout.write(text + "\n")
    else:
        Path(args.output).write_text(text + "\n", encoding="utf-8")
    return 0


def readable(value: Any) -> Any:
    """``value`` with every float rounded to 12 significant digits, which removes binary
    noise such as ``0.30000000000000004`` (a 0.1 s grid times 3) and keeps far more digits
    than any of the summary's quantities is known to."""
    if isinstance(value, float):
        return float(f"{value:.12g}")
    if isinstance(value, dict):
        return {k: readable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [readable(v) for v in value]
    return value
