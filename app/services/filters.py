"""The filters of a paged listing (``GET /catalogues/{id}/scenarios``,
``GET /evaluations/{id}/runs``, ``scengen catalogue show --filter``) from ``name=value``
pairs: ``<field>_min`` / ``<field>_max`` (inclusive, finite bounds) on the numeric fields
and ``<field>=true|false`` on the yes/no fields.

A bound must be a finite number: the stores keep an infinite value (a TTC of an opening
gap) as null, so ``ttc_max=inf`` would drop exactly the rows it seems to keep; leave a
side open instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from app.errors import InvalidInput

__all__ = ["ParsedFilters", "parse_filters"]

Range = tuple[str, float | None, float | None]


@dataclass(frozen=True)
class ParsedFilters:
    """Inclusive ranges ``(field, low, high)`` (``None``: open) and yes/no conditions."""

    ranges: tuple[Range, ...] = ()
    flags: tuple[tuple[str, bool], ...] = ()


def parse_filters(items: Sequence[tuple[str, str]], range_fields: Sequence[str],
                  flag_fields: Sequence[str], others: str = "",
                  where: str = "query") -> ParsedFilters:
    """Ranges and flags from ``name=value`` pairs; anything else is an ``InvalidInput``
    naming it as ``where.name`` (``others``: the listing's further filters, named in the
    message of an unknown one)."""
    ranges: dict[str, list[float | None]] = {}
    flags: list[tuple[str, bool]] = []
    for key, raw in items:
        name, _, bound = key.rpartition("_")
        if bound in ("min", "max") and name in range_fields:
            try:
                # ASCII digits: float() would also read '１' or '1_0'
                value = float(raw) if raw.isascii() and "_" not in raw else math.nan
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise InvalidInput(f"{key}: expected a finite number in ASCII digits, got "
                                   f"{raw!r}", field=f"{where}.{key}")
            ranges.setdefault(name, [None, None])[0 if bound == "min" else 1] = value
        elif key in flag_fields:
            if raw.lower() not in ("true", "false", "1", "0"):
                raise InvalidInput(f"{key}: expected true or false, got {raw!r}",
                                   field=f"{where}.{key}")
            flags.append((key, raw.lower() in ("true", "1")))
        else:
            raise InvalidInput(
                f"{key}: unknown filter; filters are <field>_min / <field>_max for "
                f"{', '.join(range_fields)}, <field>=true|false for "
                f"{', '.join(flag_fields)}{', and ' + others if others else ''}",
                field=f"{where}.{key}")
    return ParsedFilters(tuple((k, v[0], v[1]) for k, v in ranges.items()), tuple(flags))
