"""The options every ``scengen`` sub-command shares, and the CLI's user-facing error.

One grammar for every sub-command: the options below (``add_n``, ``add_constraints``,
``add_out``, ``add_quiet``, ``add_data_dir``) are the only way a sub-command takes a
count, constraints, an output file, silence or the store, so ``-n/--n``, ``-c/--constraint``,
``-o/--out``, ``-q/--quiet`` and ``--data-dir`` mean the same everywhere; ``add_sampler``
gives ``--sampler``.
"""

from __future__ import annotations

import argparse
from pathlib import Path


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


#: ``--sampler``'s choices: ``sampler.SAMPLER_NAMES`` (the registry ``sampler.methods.SAMPLERS``),
#: written out so that building the parser does not import the sampler (seconds: numba,
#: scipy); ``tests/app/test_cli.py`` checks that the two agree
SAMPLER_CHOICES = ("auto", "rejection", "mcmc", "subset", "subset-is")


def add_sampler(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sampler", choices=SAMPLER_CHOICES, default="auto",
                        help="sampling method (auto)")


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
