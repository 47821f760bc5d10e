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
from typing import TYPE_CHECKING, Any

from datasets.cutin_model import (
    DEFAULT_LANE_WIDTH,
    GL_NODES,
    GL_WEIGHTS,
    PANEL,
    PARAM_DOCS,
    PARAM_NAMES,
    PARAM_UNITS,
    CutInParamError,
    CutInParams,
    CutInTrajectory,
    crossing_time,
    motion,
    speed,
    trajectory,
    ttc_from_gap_dv,
)
from datasets.errors import DatasetError, ExtractionError, FormatError
from datasets.table import TABLE_COLUMNS, describe_table, read_table, write_table

if TYPE_CHECKING:  # the lazy names below, typed for mypy
    from datasets.egocentric import (
        egocentric_to_scenarios,
        read_egocentric,
        scenario_to_egocentric,
        write_egocentric,
    )
    from datasets.embedded import DEFAULT_EVENTS_PATH, default_parameter_table, load_default_events
    from datasets.embedded import SOURCE as EMBEDDED_SOURCE
    from datasets.embedded import source_hash as embedded_source_hash
    from datasets.extract import extract_cutins, extract_egocentric, extract_highd
    from datasets.highd import find_recordings, read_highd, write_highd
    from datasets.plausibility import implausible
    from datasets.surfaces_fit import (
        fit_surfaces,
        trajectories_from_egocentric,
        trajectories_from_highd,
        write_surfaces,
    )
    from datasets.synth import generate_recording, write_synthetic
    from datasets.tno import convert_tno
    from datasets.tno_package import write_tno_package

__all__ = [
    "DEFAULT_EVENTS_PATH",
    "DEFAULT_LANE_WIDTH",
    "EMBEDDED_SOURCE",
    "GL_NODES",
    "GL_WEIGHTS",
    "PANEL",
    "PARAM_DOCS",
    "PARAM_NAMES",
    "PARAM_UNITS",
    "TABLE_COLUMNS",
    "CutInParamError",
    "CutInParams",
    "CutInTrajectory",
    "DatasetError",
    "ExtractionError",
    "FormatError",
    "convert_tno",
    "crossing_time",
    "default_parameter_table",
    "describe_table",
    "egocentric_to_scenarios",
    "embedded_source_hash",
    "extract_cutins",
    "extract_egocentric",
    "extract_highd",
    "find_recordings",
    "fit_surfaces",
    "generate_recording",
    "implausible",
    "load_default_events",
    "motion",
    "read_egocentric",
    "read_highd",
    "read_table",
    "scenario_to_egocentric",
    "speed",
    "trajectories_from_egocentric",
    "trajectories_from_highd",
    "trajectory",
    "ttc_from_gap_dv",
    "write_egocentric",
    "write_highd",
    "write_surfaces",
    "write_synthetic",
    "write_table",
    "write_tno_package",
]

_LAZY = {
    "DEFAULT_EVENTS_PATH": "datasets.embedded",
    "egocentric_to_scenarios": "datasets.egocentric",
    "find_recordings": "datasets.highd",
    "implausible": "datasets.plausibility",
    "trajectories_from_egocentric": "datasets.surfaces_fit",
    "trajectories_from_highd": "datasets.surfaces_fit",
    "write_surfaces": "datasets.surfaces_fit",
    "write_synthetic": "datasets.synth",
    "write_tno_package": "datasets.tno_package",
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
    if name == "EMBEDDED_SOURCE":
        return importlib.import_module("datasets.embedded").SOURCE
    if name == "embedded_source_hash":
        return importlib.import_module("datasets.embedded").source_hash
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'datasets' has no attribute {name!r}")
