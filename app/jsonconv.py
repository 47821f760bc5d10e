"""The service's one JSON convention for non-finite floats, for JSON built outside pydantic.

Response models use pydantic's ``ser_json_inf_nan="strings"`` (``app.schemas.ApiModel``);
this module does the same for stored JSON columns and files: +inf, -inf and NaN are the
strings ``"Infinity"``, ``"-Infinity"`` and ``"NaN"``, and :func:`decode` restores them.
numpy scalars and arrays become plain Python numbers and lists.
"""

from __future__ import annotations

import math
from typing import Any

import pydantic_core

__all__ = ["decode", "dumps", "encode", "plot_values"]

_NONFINITE = {"Infinity": math.inf, "-Infinity": -math.inf, "NaN": math.nan}


def _plain(value: Any) -> Any:
    # numpy values: pydantic_core serialises numpy arrays and scalars only via tolist/item
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def dumps(value: Any) -> str:
    """JSON text of ``value`` with non-finite floats as strings."""
    return pydantic_core.to_json(value, inf_nan_mode="strings", fallback=_plain).decode()


def encode(value: Any) -> Any:
    """``value`` as plain JSON types with non-finite floats as strings (for JSON columns)."""
    return pydantic_core.from_json(dumps(value))


def decode(value: Any) -> Any:
    """Inverse of :func:`encode`: the strings back to floats, recursively."""
    if isinstance(value, dict):
        return {k: decode(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode(v) for v in value]
    if isinstance(value, str) and value in _NONFINITE:
        return _NONFINITE[value]
    return value


def plot_values(value: Any) -> Any:
    """Plot data for the dashboard: like :func:`encode` but non-finite floats become null,
    which plotly draws as a gap (the one place where the service writes null for inf)."""
    if isinstance(value, dict):
        return {str(k): plot_values(v) for k, v in value.items()}
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return [plot_values(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value
