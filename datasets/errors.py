"""Exception hierarchy of ``datasets``.

::

    DatasetError (riskcore.FieldError)   any problem with input data or its use
    ├── FormatError                      a file or frame breaks its format (names file/column/row)
    ├── ExtractionError                  a cut-in could not be extracted or fitted
    └── CutInParamError                  a parameter vector is incomplete or out of range
                                         (datasets.cutin_model)

The base is the project's neutral ``FieldError`` (the tree is drawn in riskcore/errors.py),
so the CLI turns them into one line and exit code 2 and the service into a 422.
"""

from __future__ import annotations

from riskcore import FieldError

__all__ = ["DatasetError", "ExtractionError", "FormatError"]


class DatasetError(FieldError):
    """Base class of every error raised by ``datasets`` on bad input."""


class FormatError(DatasetError):
    """A file or data frame does not follow its format.

    The message names the file (or frame), the column and the row when they are known.
    """


class ExtractionError(DatasetError):
    """A cut-in could not be extracted (too short, never crosses the marking, fit failed)."""
