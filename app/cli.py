"""The ``scengen`` command line.

Each command group lives in its own module with a ``register(subparsers)`` function that
adds its sub-commands; a sub-command stores its handler as ``func`` and the handler returns
the exit code. Errors a user can cause (bad files, bad values) are ``ValueError`` or
``OSError`` subclasses: they end as one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from app import __version__

#: modules that contribute sub-commands, in the order they appear in ``--help``
COMMAND_MODULES: tuple[str, ...] = (
    "app.cli_risk",  # scengen risk
    "app.cli_data",  # scengen data ...
    "app.cli_sampler",  # scengen fit, scengen sample
    "app.cli_service",  # scengen serve, scengen catalogue ...
)


class CliError(Exception):
    """A user-facing failure: printed as one line, exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="scengen",
        description="Generate and score risk-constrained cut-in test scenarios.",
    )
    parser.add_argument("--version", action="version", version=f"scengen {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(func(args) or 0)
    except KeyboardInterrupt:
        print("scengen: interrupted", file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError, LookupError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"scengen: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
