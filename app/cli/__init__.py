"""The ``scengen`` command line (entry point ``app.cli:main``).

- ``app.cli.main``      the parser, ``main()``, one-line errors and exit codes
- ``app.cli.options``   the options every sub-command shares (``-n``, ``-c``, ``-o``, ``-q``,
                        ``--data-dir``) and ``CliError``
- ``app.cli.risk``      ``scengen risk``
- ``app.cli.data``      ``scengen data ...``
- ``app.cli.sampling``  ``scengen fit``, ``scengen sample``
- ``app.cli.service``   ``scengen serve``, ``scengen catalogue ...``
"""

from app.cli.main import build_parser, main, one_line
from app.cli.options import CliError

__all__ = ["CliError", "build_parser", "main", "one_line"]
