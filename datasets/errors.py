"""Exception hierarchy of ``datasets``.

::

    DatasetError (ValueError)          any problem with input data or its use
    ├── FormatError                    a file or frame breaks its format (names file/column/row)
    └── ExtractionError                a cut-in could not be extracted or fitted

All are ``ValueError`` subclasses, so the CLI turns them into one line and exit code 2.
"""

from __future__ import annotations

__all__ = ["DatasetError", "ExtractionError", "FormatError"]


class DatasetError(ValueError):
    """Base class of every error raised by ``datasets`` on bad input."""


class FormatError(DatasetError):
    """A file or data frame does not follow its format.

    The message names the file (or frame), the column and the row when they are known.
    """


class ExtractionError(DatasetError):
    """A cut-in could not be extracted (too short, never crosses the marking, fit failed)."""
