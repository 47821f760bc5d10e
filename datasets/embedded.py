"""The embedded default data set: real TNO cut-ins (MIT), shipped in ``datasets/data``.

``datasets/data/tno_cutin/`` holds the ego-centric conversion of the 297 cut-ins of
de Gelder et al. (2021) made by ``scengen data convert-tno`` (implausible events left
out), the MIT licence of the source and ``PROVENANCE.md``.
"""

from __future__ import annotations

import hashlib
import importlib
from functools import lru_cache
from pathlib import Path

import pandas as pd

from datasets.egocentric import read_egocentric

__all__ = [
    "DEFAULT_EVENTS_PATH",
    "EMBEDDED_DIR",
    "SOURCE",
    "default_parameter_table",
    "load_default_events",
    "source_hash",
]

#: folder of the embedded data set
EMBEDDED_DIR = Path(__file__).resolve().parent / "data" / "tno_cutin"
#: the ego-centric events file
DEFAULT_EVENTS_PATH = EMBEDDED_DIR / "tno_cutin_egocentric.parquet"
#: the ``source`` column value of the embedded table
SOURCE = "tno-cutin (de Gelder et al. 2021, MIT)"


@lru_cache(maxsize=1)
def _events() -> pd.DataFrame:
    return read_egocentric(DEFAULT_EVENTS_PATH)


def load_default_events() -> pd.DataFrame:
    """The embedded real cut-ins in the ego-centric format (a fresh copy on each call).

    Returns
    -------
    DataFrame
        One row per 0.1 s per event; columns of :data:`datasets.egocentric.EGO_COLUMNS`.
    """
    return _events().copy()


@lru_cache(maxsize=1)
def _table() -> pd.DataFrame:
    from datasets.extract import extract_egocentric

    return extract_egocentric(_events(), source=SOURCE)


def default_parameter_table() -> pd.DataFrame:
    """The parameter table extracted from the embedded events (computed once, then cached).

    Returns a fresh copy on each call, so callers may modify it.
    """
    return _table().copy()


#: modules whose code turns the embedded events into the parameter table (in hashing order)
_EXTRACTION_MODULES = ("datasets.cutin_model", "datasets.egocentric", "datasets.extract",
                       "datasets.embedded")


def source_hash() -> str:
    """sha256 of the embedded events file and of the extraction code: a key under which a
    caller may cache the parameter table (extraction takes tens of seconds); it changes
    when the data or the code that extracts it does."""
    digest = hashlib.sha256()
    digest.update(DEFAULT_EVENTS_PATH.read_bytes())
    for name in _EXTRACTION_MODULES:
        digest.update(Path(str(importlib.import_module(name).__file__)).read_bytes())
    return digest.hexdigest()
