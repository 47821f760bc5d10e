"""The ``scengen`` command line.

Each command group lives in its own module with a ``register(subparsers)`` function that
adds its sub-commands; a sub-command stores its handler as ``func`` and the handler returns
the exit code. Errors a user can cause (bad files, bad values) are ``riskcore.FieldError``
(the project's one error tree, drawn in riskcore/errors.py), ``CliError``, ``OSError`` or the
service's ``ServiceError``: they end as one line on stderr and exit code 2, never a
traceback. Anything else is our bug: one line that says so and exit code 70, the trace
with ``SCENGEN_DEBUG=1``. Output cut short by the reader (``scengen risk f.json |
head``) ends quietly. The options every sub-command shares are in ``app.cli.options``.

A command is a thin wrapper over ``app.services`` (or a domain package's function): it
reads its arguments, calls the use case and prints. Handlers import the services when
they run, not at module import, so that ``scengen --help`` and argument errors answer in
0.2 s instead of the 3-6 s numba, scikit-learn and the store take to load.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from app import __version__
from app.cli.options import CliError, add_data_dir

#: exit code of an internal error (BSD's EX_SOFTWARE)
EXIT_INTERNAL = 70

#: modules that contribute sub-commands, in the order they appear in ``--help``
COMMAND_MODULES: tuple[str, ...] = (
    "app.cli.risk",  # scengen risk
    "app.cli.data",  # scengen data ...
    "app.cli.sampling",  # scengen fit, scengen sample
    "app.cli.service",  # scengen serve, scengen catalogue ...
    "app.cli.evaluate",  # scengen evaluate
)


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


#: the user's errors besides ``CliError``, ``OSError`` and ``LookupError``, as (module,
#: class); looked up only in modules already imported: an exception of a class whose
#: module was never imported cannot have been raised. Importing them up front (riskcore,
#: FastAPI: 2.4 s) delayed every command, and ``catalogue create`` starts its pool's
#: workers before the heavy imports so that they overlap (issue 25 item 7).
USER_ERRORS: tuple[tuple[str, str], ...] = (
    ("app.errors", "ServiceError"),
    ("riskcore.errors", "FieldError"),
)


def user_error_types() -> tuple[type[BaseException], ...]:
    """The exception classes that end as one line and exit code 2."""
    found: list[type[BaseException]] = [CliError, OSError, LookupError]
    for module, name in USER_ERRORS:
        loaded = sys.modules.get(module)
        if loaded is not None:
            found.append(getattr(loaded, name))
    return tuple(found)


def main(argv: Sequence[str] | None = None) -> int:
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
    except Exception as exc:
        if isinstance(exc, user_error_types()):
            print(f"scengen: error: {one_line(exc)}", file=sys.stderr)
            return 2
        # a bug of ours (or a library's), never the user's input
        if os.environ.get("SCENGEN_DEBUG"):
            traceback.print_exc()
        print(f"scengen: internal error (please report it; SCENGEN_DEBUG=1 shows the trace): "
              f"{type(exc).__name__}: {one_line(exc)}", file=sys.stderr)
        return EXIT_INTERNAL


def one_line(exc: BaseException) -> str:
    """The first line of an error's message (its type name when it has none); a file
    system error as "<file>: <what>" in words, not Python's "[Errno 2] ..." (issue 25)."""
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        what = {FileNotFoundError: "no such file", IsADirectoryError: "is a directory, "
                "not a file", PermissionError: "permission denied"}.get(
                    type(exc), exc.strerror.lower())
        return f"{exc.filename}: {what}"
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
