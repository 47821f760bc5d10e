"""The public functions of ``app.exports``; the format writers live in private modules."""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from app import __version__
from app.atomic import atomic_path
from app.exports._common import (
    ExportError,
    Row,
    check_flat_value,
    jsonable,
)
from app.versions import LIBRARIES, versions
from datasets import PARAM_NAMES, ttc_from_gap_dv
from riskcore import ConcreteScenario
from sampler.scenario import SCORE_FIELDS

#: The formats ``export_catalogue`` writes.
EXPORT_FORMATS: tuple[str, ...] = ("jsonl", "csv", "parquet", "xosc", "commonroad")

#: Identifier columns, first in every row (``export_catalogue`` puts ``index`` before them).
ID_COLUMNS: tuple[str, ...] = ("scenario_id", "seed")

#: Columns computed from the scenario itself, after the parameters.
DERIVED_COLUMNS: tuple[str, ...] = ("ttc", "duration", "dt", "n_steps", "n_objects")

#: Score columns in their fixed order (always present, None when the summary lacks them):
#: the scored record's fields after ``ttc`` (``sampler.scenario.record.ScenarioRecord``):
#: ``exposure_weight`` (the scenario's share of P(A)), the criticality record
#: (``SCORE_FIELDS`` = ``riskcore.criticality.CRITICALITY_FIELDS``, in its order; +inf is
#: kept, e.g. ``ttr_true`` without a collision course) and ``error`` (why a vector has no
#: scores). Any other summary key follows, sorted by name.
SUMMARY_COLUMNS: tuple[str, ...] = ("exposure_weight", *SCORE_FIELDS, "error")

#: Column names the exports add themselves (``index``: position in the catalogue; ``file``:
#: the .xosc name in the xosc zip's catalogue.csv); a summary may not use them.
RESERVED_COLUMNS: tuple[str, ...] = ("index", "file")

#: ``format`` field of every manifest ``build_manifest`` returns.
MANIFEST_FORMAT = "scengen.catalogue-manifest/1"

#: Packages whose versions go into every manifest: the service's one list
#: (``app.versions.LIBRARIES``; scengen itself first).
VERSION_PACKAGES: tuple[str, ...] = LIBRARIES


def _scenario_id(scenario: ConcreteScenario, summary: Mapping[str, Any]) -> Any:
    if "scenario_id" in summary:
        return summary["scenario_id"]
    for key in ("scenario_id", "id"):
        value = scenario.provenance.get(key)
        if isinstance(value, str | int) and not isinstance(value, bool):
            return value
    return None


def _put(row: Row, key: str, value: Any, where: str) -> None:
    """Set ``row[key]``; a key already holding a *different* non-None value is an error."""
    old = row.get(key)
    if old is not None and value is not None and not _same(old, value):
        raise ExportError(
            f"{where}: column {key!r} = {value!r} conflicts with the value {old!r} "
            "computed from the scenario; rename the summary key"
        )
    if value is not None or key not in row:
        row[key] = value


def _same(a: Any, b: Any) -> bool:
    def is_number(v: Any) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    if is_number(a) and is_number(b):
        fa, fb = float(a), float(b)
        return fa == fb or (math.isnan(fa) and math.isnan(fb))
    return type(a) is type(b) and bool(a == b)


def scenario_row(scenario: ConcreteScenario, summary: Mapping[str, Any]) -> dict[str, Any]:
    """One flat row for a scenario: identifiers, parameters, derived values and scores.

    Parameters
    ----------
    scenario : ConcreteScenario
    summary : mapping of str to number, string or None
        The scores (the record's ``SCORE_FIELDS``) and anything the caller adds
        (``exposure_weight``, ``error``, ``scenario_id``...). May be empty for unscored
        scenarios.

    Returns
    -------
    dict
        Columns in a stable order: ``ID_COLUMNS`` (``scenario_id`` from the summary, else
        the scenario's provenance ``scenario_id``/``id``; ``seed``), the ``PARAM_NAMES`` in
        order (None when the scenario has no such parameter), any other parameters sorted,
        ``DERIVED_COLUMNS`` (``ttc`` = gap/dv when dv > 0 else inf, s; ``duration`` s;
        ``dt`` median step s; ``n_steps``; ``n_objects``), ``SUMMARY_COLUMNS`` in order
        (None when absent), then every other summary key sorted by name. Values are
        Python ``float``/``int``/``bool``/``str``/None.

    Raises
    ------
    ExportError
        A summary key is not a string or is one of ``RESERVED_COLUMNS``, a value is not a
        number/string/None, or a summary value contradicts a column computed from the
        scenario.
    """
    if not isinstance(scenario, ConcreteScenario):
        raise ExportError(f"scenario: expected a ConcreteScenario, got {type(scenario).__name__}")
    if not isinstance(summary, Mapping):
        raise ExportError(f"summary: expected a mapping, got {type(summary).__name__}")
    clean: dict[str, Any] = {}
    for key, value in summary.items():
        if not isinstance(key, str) or not key:
            raise ExportError(f"summary: keys must be non-empty strings, got {key!r}")
        if key in RESERVED_COLUMNS:
            raise ExportError(f"summary[{key!r}]: the column name {key!r} is reserved by "
                              "the exports; rename it")
        clean[key] = check_flat_value(value, f"summary[{key!r}]")

    row: Row = {}
    row["scenario_id"] = check_flat_value(_scenario_id(scenario, clean), "scenario_id")
    row["seed"] = scenario.seed
    params = scenario.params
    for name in PARAM_NAMES:
        row[name] = float(params[name]) if name in params else None
    for name in sorted(set(params) - set(PARAM_NAMES)):
        if name in RESERVED_COLUMNS:
            raise ExportError(f"params[{name!r}]: the column name {name!r} is reserved by "
                              "the exports; rename the parameter")
        _put(row, name, float(params[name]), f"params[{name!r}]")
    if "gap" in params and "dv" in params:
        row["ttc"] = float(ttc_from_gap_dv(params["gap"], params["dv"]))
    else:
        row["ttc"] = None
    t = scenario.t
    # differences of grid times carry float noise (10.6 - 10.5 = 0.09999999999999964);
    # a picosecond is far below any step a scenario uses
    row["duration"] = round(float(t[-1] - t[0]), 12)
    row["dt"] = round(scenario.dt, 12)
    row["n_steps"] = int(t.shape[0])
    row["n_objects"] = len(scenario.objects)
    for name in SUMMARY_COLUMNS:
        _put(row, name, clean.get(name), f"summary[{name!r}]")
    for name in sorted(set(clean) - set(SUMMARY_COLUMNS) - {"scenario_id"}):
        _put(row, name, clean[name], f"summary[{name!r}]")
    return row


def build_manifest(
    *,
    seed: int | None,
    model_hash: str | None,
    sampler_settings: Mapping[str, Any],
    constraints: Iterable[str] | Mapping[str, Any],
    p_region: float | Mapping[str, Any] | None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The provenance record that travels with every export.

    Parameters
    ----------
    seed : int or None
        The catalogue's seed.
    model_hash : str or None
        Identifies the fitted model (e.g. the sha256 of its JSON).
    sampler_settings : mapping
        Method and options of the sampler (JSON-able values).
    constraints : iterable of str, or mapping
        The risk-region constraints, e.g. ``["ttc<3"]``.
    p_region : float, mapping or None
        P(A), the probability of the region under the model, optionally with its
        confidence interval (``{"estimate": ..., "ci": [lo, hi]}``).
    extra : mapping, optional
        More top-level fields (e.g. ``catalogue_id``, ``created_at``); they may not
        replace the standard ones.

    Returns
    -------
    dict
        ``{"format": MANIFEST_FORMAT, "seed", "model_hash", "sampler_settings",
        "constraints", "p_region", "versions": {package: version or None}, "note"}`` plus
        the ``extra`` fields. JSON-able; no wall-clock time unless ``extra`` brings one, so
        the same inputs give the same manifest.

    Raises
    ------
    ExportError
        A field has the wrong type or is not JSON-able; the message names it.
    """
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ExportError(f"seed: expected an integer or None, got {seed!r}")
    if model_hash is not None and not isinstance(model_hash, str):
        raise ExportError(f"model_hash: expected a string or None, got {model_hash!r}")
    if not isinstance(sampler_settings, Mapping):
        raise ExportError(
            f"sampler_settings: expected a mapping, got {type(sampler_settings).__name__}"
        )
    if isinstance(constraints, str):
        constraints_out: Any = [constraints]
    elif isinstance(constraints, Mapping):
        constraints_out = jsonable(constraints, "constraints")
    else:
        try:
            constraints_out = list(constraints)
        except TypeError:
            raise ExportError(
                f"constraints: expected a list of strings or a mapping, got "
                f"{type(constraints).__name__}"
            ) from None
        for i, c in enumerate(constraints_out):
            if not isinstance(c, str):
                raise ExportError(f"constraints[{i}]: expected a string, got {c!r}")
    if p_region is not None and not isinstance(p_region, Mapping):
        if isinstance(p_region, bool) or not isinstance(p_region, int | float):
            raise ExportError(f"p_region: expected a number, mapping or None, got {p_region!r}")
        p_region = float(p_region)
    manifest: dict[str, Any] = {
        "format": MANIFEST_FORMAT,
        "seed": seed,
        "model_hash": model_hash,
        "sampler_settings": jsonable(sampler_settings, "sampler_settings"),
        "constraints": constraints_out,
        "p_region": jsonable(p_region, "p_region"),
        "versions": package_versions(),
        "note": (
            f"created by scengen {__version__}; no wall-clock timestamp is recorded so that "
            "the same inputs give byte-identical exports"
        ),
    }
    if extra is not None:
        if not isinstance(extra, Mapping):
            raise ExportError(f"extra: expected a mapping, got {type(extra).__name__}")
        for key, value in extra.items():
            if not isinstance(key, str):
                raise ExportError(f"extra: keys must be strings, got {key!r}")
            if key in manifest:
                raise ExportError(f"extra[{key!r}]: would replace a standard manifest field")
            manifest[key] = jsonable(value, f"extra[{key!r}]")
    return manifest


def package_versions() -> dict[str, str | None]:
    """Installed versions of scengen and the packages behind its numbers (None: absent)."""
    return versions(VERSION_PACKAGES)


def export_catalogue(
    fmt: str,
    items: Iterable[tuple[ConcreteScenario, Mapping[str, Any]]],
    manifest: Mapping[str, Any],
    out: str | os.PathLike[str],
    *,
    mode: str | None = None,
) -> Path:
    """Write a catalogue to ``out`` in format ``fmt``; stream the items; return the path.

    Parameters
    ----------
    fmt : {"jsonl", "csv", "parquet", "xosc", "commonroad"}
    items : iterable of (ConcreteScenario, mapping)
        Consumed once, one item at a time (a generator is fine). Each scenario needs at
        least one object besides the ego.
    manifest : mapping
        Usually from ``build_manifest``; JSON-able.
    out : path
        The file to write (for ``xosc`` a zip). Its directory must exist. The file is
        written under a temporary name next to it and renamed when complete, so a failed
        export leaves nothing behind.
    mode : {"test", "replay"}, optional
        OpenSCENARIO mode of the ``xosc`` export (default ``"test"``: the ego is the system
        under test; ``"replay"``: both vehicles scripted). Only for ``xosc``.

    Raises
    ------
    ExportError
        Unknown format, empty catalogue, a scenario without objects, a row whose columns
        differ from the first row's, a value of the wrong type, an OpenSCENARIO/OpenDRIVE
        file that fails XSD validation... The message names the item index.
    """
    if fmt not in EXPORT_FORMATS:
        raise ExportError(f"format: unknown export format {fmt!r}; choose one of "
                          f"{', '.join(EXPORT_FORMATS)}")
    if not isinstance(manifest, Mapping):
        raise ExportError(f"manifest: expected a mapping, got {type(manifest).__name__}")
    if mode is not None and fmt != "xosc":
        raise ExportError(f"mode: only the xosc export has modes, not {fmt!r}")
    manifest_clean = jsonable(manifest, "manifest")
    out_path = Path(out)
    if not out_path.parent.is_dir():
        raise ExportError(f"out: directory {str(out_path.parent)!r} does not exist")
    if out_path.is_dir():
        raise ExportError(f"out: {str(out_path)!r} is a directory, expected a file path")
    checked = _checked_items(items)
    with atomic_path(out_path) as tmp:
        if fmt == "jsonl":
            from app.exports._jsonl import write_jsonl

            write_jsonl(checked, manifest_clean, tmp)
        elif fmt == "csv":
            from app.exports._tabular import write_csv

            write_csv(checked, tmp)
        elif fmt == "parquet":
            from app.exports._tabular import write_parquet

            write_parquet(checked, manifest_clean, tmp)
        elif fmt == "commonroad":
            from app.exports._commonroad import write_commonroad_zip

            write_commonroad_zip(checked, manifest_clean, tmp)
        else:
            from app.exports._xosc import check_mode, write_xosc_zip

            write_xosc_zip(checked, manifest_clean, tmp, check_mode(mode or "test"))
    return out_path


def _checked_items(
    items: Iterable[tuple[ConcreteScenario, Mapping[str, Any]]],
) -> Iterator[tuple[int, ConcreteScenario, Mapping[str, Any], Row]]:
    """Validate each item as it streams by; yield (index, scenario, summary, row)."""
    if isinstance(items, str | bytes | Mapping):
        raise ExportError(
            f"items: expected an iterable of (scenario, summary) pairs, got "
            f"{type(items).__name__}"
        )
    try:
        iterator = iter(items)
    except TypeError:
        raise ExportError(
            f"items: expected an iterable of (scenario, summary) pairs, got "
            f"{type(items).__name__}"
        ) from None
    count = 0
    for index, item in enumerate(iterator):
        if not isinstance(item, tuple | list) or len(item) != 2:
            raise ExportError(f"item {index}: expected a (scenario, summary) pair")
        scenario, summary = item
        if not isinstance(scenario, ConcreteScenario):
            raise ExportError(
                f"item {index}: expected a ConcreteScenario, got {type(scenario).__name__}"
            )
        if not scenario.objects:
            raise ExportError(
                f"item {index}: the scenario has no objects besides the ego; a cut-in "
                "catalogue needs at least the cutting-in vehicle"
            )
        try:
            row = scenario_row(scenario, summary)
        except ExportError as exc:
            raise ExportError(f"item {index}: {exc}") from None
        count += 1
        yield index, scenario, summary, row
    if count == 0:
        raise ExportError("items: the catalogue is empty; nothing to export")


def read_jsonl_manifest(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The manifest (first line) of a JSONL export."""
    from app.exports._jsonl import read_manifest

    return read_manifest(Path(path))


def read_jsonl(
    path: str | os.PathLike[str],
) -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
    """Stream the (scenario, summary) pairs back from a JSONL export, in order."""
    from app.exports._jsonl import read_items

    return read_items(Path(path))
