"""datasets: trajectory readers/writers, cut-in extraction, embedded data, surface fitting.

Public surface (see docs/datasets.md):

- formats: :func:`read_egocentric`, :func:`write_egocentric`, :func:`scenario_to_egocentric`
  (ego-centric, CSV/Parquet); :func:`read_highd`, :func:`write_highd` (highD CSVs);
- extraction: :func:`extract_egocentric`, :func:`extract_highd`, :func:`extract_cutins`
  and the column list :data:`TABLE_COLUMNS` of the parameter table;
- data: :func:`load_default_events`, :func:`default_parameter_table` (real TNO cut-ins),
  :func:`convert_tno`, :func:`generate_recording` (synthetic highD);
- :func:`fit_surfaces` (riskcore's input-distribution surfaces from trajectories).

Heavier modules are imported lazily, so ``import datasets`` stays cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

from datasets.cutin_model import PARAM_NAMES, CutInParams
from datasets.errors import DatasetError, ExtractionError, FormatError
from datasets.table import TABLE_COLUMNS

__all__ = [
    "PARAM_NAMES",
    "TABLE_COLUMNS",
    "CutInParams",
    "DatasetError",
    "ExtractionError",
    "FormatError",
    "convert_tno",
    "default_parameter_table",
    "extract_cutins",
    "extract_egocentric",
    "extract_highd",
    "fit_surfaces",
    "generate_recording",
    "load_default_events",
    "read_egocentric",
    "read_highd",
    "scenario_to_egocentric",
    "write_egocentric",
    "write_highd",
]

_LAZY = {
    "convert_tno": "datasets.tno",
    "default_parameter_table": "datasets.embedded",
    "load_default_events": "datasets.embedded",
    "extract_cutins": "datasets.extract",
    "extract_egocentric": "datasets.extract",
    "extract_highd": "datasets.extract",
    "fit_surfaces": "datasets.surfaces_fit",
    "generate_recording": "datasets.synth",
    "read_egocentric": "datasets.egocentric",
    "write_egocentric": "datasets.egocentric",
    "scenario_to_egocentric": "datasets.egocentric",
    "read_highd": "datasets.highd",
    "write_highd": "datasets.highd",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'datasets' has no attribute {name!r}")
