"""Test-catalogue exports: JSONL, CSV, Parquet and OpenSCENARIO (zip).

A catalogue is an iterable of ``(ConcreteScenario, summary)`` pairs, where ``summary`` is a
flat mapping of numbers, strings and None (``riskcore``'s ``ScenarioRisk.summary()`` plus
whatever the caller adds, e.g. the exposure weight). Exports are streamed: the items are
consumed one at a time and written incrementally, so a 100,000-scenario catalogue never
sits in memory. The same items and manifest always give byte-identical files.

Formats (``EXPORT_FORMATS``), details in docs/exports.md:

``jsonl``
    Line 1 is ``{"kind": "manifest", "manifest": {...}}``; every further line is
    ``{"kind": "scenario", "index": i, "scenario": {...}, "summary": {...}}``
    with the full concrete scenario in its JSON form (``ConcreteScenario.to_dict()``).
    Strict JSON: non-finite numbers in the summary/manifest are written as the strings
    ``"Infinity"``, ``"-Infinity"``, ``"NaN"``; ``read_jsonl`` turns them back into floats,
    so the round trip is lossless.
``csv``
    One row per scenario (``scenario_row``), a header line, RFC 4180 quoting, floats in
    shortest round-trip form (``inf`` for infinities), empty cell for None.
``parquet``
    The same rows, written in row groups with ``pyarrow.parquet.ParquetWriter``; the
    manifest is stored as JSON in the file's key-value metadata under ``scengen.manifest``.
``xosc``
    One zip: ``manifest.json``, ``scenario_NNNNNNN.xosc`` (OpenSCENARIO 1.2, one per
    scenario, mode ``test`` (default: the ego is the system under test, the cutter starts
    on a trigger) or ``replay`` (both scripted); positions are rear axles), the catalogue
    as one logical scenario (``cutin_logical.xosc`` + ``cutin_distribution.xosc``) and one
    shared straight multi-lane OpenDRIVE road ``road.xodr``. Every file is validated
    against the XSD that ``scenariogeneration`` ships.

Public API
----------
- ``EXPORT_FORMATS``
- ``ExportError`` (a ``riskcore.FieldError``): bad input; the message names what is wrong.
- ``scenario_row(scenario, summary) -> dict``
- ``export_catalogue(fmt, items, manifest, out, *, mode=None) -> Path``
- ``build_manifest(*, seed, model_hash, sampler_settings, constraints, p_region, extra=None)``
- ``read_jsonl(path) -> Iterator[tuple[ConcreteScenario, dict]]`` and
  ``read_jsonl_manifest(path) -> dict``
- Column order: ``ID_COLUMNS``, the parameters (``datasets.cutin_model.PARAM_NAMES``),
  ``DERIVED_COLUMNS``, ``SUMMARY_COLUMNS``; ``RESERVED_COLUMNS`` (``index``, ``file``) are
  added by the exports themselves. ``MANIFEST_FORMAT`` tags every manifest.
"""

from __future__ import annotations

from app.exports._api import (
    DERIVED_COLUMNS,
    EXPORT_FORMATS,
    ID_COLUMNS,
    MANIFEST_FORMAT,
    RESERVED_COLUMNS,
    SUMMARY_COLUMNS,
    build_manifest,
    export_catalogue,
    read_jsonl,
    read_jsonl_manifest,
    scenario_row,
)
from app.exports._common import ExportError

__all__ = [
    "DERIVED_COLUMNS",
    "EXPORT_FORMATS",
    "ID_COLUMNS",
    "MANIFEST_FORMAT",
    "RESERVED_COLUMNS",
    "SUMMARY_COLUMNS",
    "ExportError",
    "build_manifest",
    "export_catalogue",
    "read_jsonl",
    "read_jsonl_manifest",
    "scenario_row",
]
