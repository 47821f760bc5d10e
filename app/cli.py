"""The ``scengen`` command line.

Each command group lives in its own module with a ``register(subparsers)`` function that
adds its sub-commands; a sub-command stores its handler as ``func`` and the handler returns
the exit code. Errors a user can cause (bad files, bad values) are ``ValueError`` or
``OSError`` subclasses (or the service's ``ServiceError``): they end as one line on stderr
and exit code 2, never a traceback. Output cut short by the reader (``scengen risk f.json |
head``) ends quietly.

One grammar for every sub-command: the options below (``add_n``, ``add_constraints``,
``add_out``, ``add_quiet``, ``add_data_dir``) are the only way a sub-command takes a
count, constraints, an output file, silence or the store, so ``-n/--n``, ``-c/--constraint``,
``-o/--out``, ``-q/--quiet`` and ``--data-dir`` mean the same everywhere.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

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


# --------------------------------------------------------------------------- shared options
def add_n(parser: argparse.ArgumentParser, *, default: int | None, what: str) -> None:
    """``-n/--n N``: how many (required when ``default`` is None)."""
    parser.add_argument("-n", "--n", dest="n", type=int, default=default,
                        required=default is None, metavar="N",
                        help=f"number of {what}" + (f" ({default})" if default else ""))


def add_constraints(parser: argparse.ArgumentParser, *, default_text: str) -> None:
    """``-c/--constraint EXPR`` (repeatable) into ``args.constraints``."""
    parser.add_argument("-c", "--constraint", action="append", dest="constraints",
                        default=None, metavar="EXPR",
                        help="risk-region constraint such as 'ttc<3' or 'v_ego>=20' "
                        f"(repeatable; all must hold; default: {default_text})")


def add_out(parser: argparse.ArgumentParser, *, required: bool, help: str,
            default: str | None = None, metavar: str = "FILE") -> None:
    """``-o/--out FILE`` into ``args.output`` (``--output`` is kept as an alias)."""
    parser.add_argument("-o", "--out", "--output", dest="output", required=required,
                        default=default, metavar=metavar, help=help)


def add_quiet(parser: argparse.ArgumentParser) -> None:
    """``-q/--quiet`` (``--no-progress`` is kept as an alias): no progress bars."""
    parser.add_argument("-q", "--quiet", "--no-progress", dest="quiet", action="store_true",
                        help="no progress bars")


def add_data_dir(parser: argparse.ArgumentParser, *, top_level: bool = False) -> None:
    """``--data-dir DIR``: the store (else SCENGEN_DATA_DIR, else the per-user default)."""
    parser.add_argument(
        "--data-dir", dest="data_dir", type=Path, metavar="DIR",
        default=None if top_level else argparse.SUPPRESS,
        help="the store: database, uploads, models, catalogue files (default: "
        "SCENGEN_DATA_DIR, else the per-user data directory, see 'scengen serve --help')")


def store_label() -> str:
    """Where the CLI's store is, for messages ("... not found in the store at X")."""
    from app.settings import get_settings

    settings = get_settings()
    if settings.database_url:
        from sqlalchemy.engine import make_url

        return make_url(settings.database_url).render_as_string(hide_password=True)
    return str(Path(settings.data_dir).resolve())


def _use_data_dir(args: argparse.Namespace) -> None:
    data_dir: Path | None = getattr(args, "data_dir", None)
    if data_dir is None:
        return
    from app.settings import get_settings

    os.environ["SCENGEN_DATA_DIR"] = str(data_dir.expanduser().resolve())
    get_settings.cache_clear()


def _quiet_broken_pipe() -> None:
    # the reader went away (``| head``): send the rest of stdout nowhere, so that the
    # interpreter's final flush does not complain either
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # pragma: no cover - stdout is odd
        pass


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are one line too (sub-parsers inherit the class)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="scengen",
        description="Generate and score risk-constrained cut-in test scenarios.",
    )
    parser.add_argument("--version", action="version", version=f"scengen {__version__}")
    add_data_dir(parser, top_level=True)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from app.errors import ServiceError

    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        _use_data_dir(args)
        code = int(func(args) or 0)
        sys.stdout.flush()
        return code
    except KeyboardInterrupt:
        print("scengen: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _quiet_broken_pipe()
        return 0
    except (CliError, ServiceError, ValueError, OSError, LookupError) as exc:
        print(f"scengen: error: {one_line(exc)}", file=sys.stderr)
        return 2


def one_line(exc: BaseException) -> str:
    """The first line of an error's message (its type name when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
