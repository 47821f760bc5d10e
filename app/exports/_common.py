"""Shared pieces of the export writers: the error type, value checks, strict JSON."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from riskcore import FieldError

#: One flat row: column name -> float | int | bool | str | None.
Row = dict[str, Any]

#: How non-finite floats are spelled in our strict JSON (and read back).
NONFINITE_TOKENS: dict[str, float] = {
    "Infinity": math.inf,
    "-Infinity": -math.inf,
    "NaN": math.nan,
}


class ExportError(FieldError):
    """An export cannot be written from this input. The message names what is wrong (a
    ``riskcore.FieldError``: the user's input, not our bug)."""


def check_flat_value(value: Any, where: str) -> Any:
    """A number, string, bool or None as a plain Python value; anything else is an error."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    raise ExportError(f"{where}: expected a number, string or None, got {type(value).__name__}")


def jsonable(value: Any, where: str) -> Any:
    """A deep copy made of dict/list/str/int/float/bool/None, or ExportError naming the path.

    Tuples and numpy arrays become lists, numpy scalars Python numbers. Non-finite floats
    stay floats here; ``dumps`` spells them as strings.
    """
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise ExportError(f"{where}: keys must be strings, got {key!r}")
            out[key] = jsonable(item, f"{where}.{key}")
        return out
    if isinstance(value, list | tuple):
        return [jsonable(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), where)
    try:
        return check_flat_value(value, where)
    except ExportError:
        raise ExportError(
            f"{where}: expected JSON-able data (mapping, list, number, string, None), got "
            f"{type(value).__name__}"
        ) from None


def encode_nonfinite(value: Any) -> Any:
    """Replace non-finite floats (deeply) by the strings of ``NONFINITE_TOKENS``."""
    if isinstance(value, float) and not math.isfinite(value):
        if math.isnan(value):
            return "NaN"
        return "Infinity" if value > 0 else "-Infinity"
    if isinstance(value, dict):
        return {k: encode_nonfinite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [encode_nonfinite(v) for v in value]
    return value


def decode_nonfinite(value: Any) -> Any:
    """Inverse of ``encode_nonfinite``: the token strings become floats again (deeply)."""
    if isinstance(value, str) and value in NONFINITE_TOKENS:
        return NONFINITE_TOKENS[value]
    if isinstance(value, dict):
        return {k: decode_nonfinite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_nonfinite(v) for v in value]
    return value


def dumps(value: Any, *, indent: int | None = None) -> str:
    """Strict JSON (no NaN/Infinity literals), keys in insertion order, UTF-8 kept."""
    separators = (",", ":") if indent is None else (",", ": ")
    return json.dumps(
        encode_nonfinite(value), allow_nan=False, ensure_ascii=False, indent=indent,
        separators=separators,
    )
