"""The one owner of the catalogue chunk files: where they live, how they are written and read.

A chunk file holds the concrete scenarios of one chunk as gzip'd JSON lines (one
``scengen.concrete-scenario/1`` object per line, in index order; ``null`` for a vector the
builder refused, whose row carries the error), written with a fixed
gzip mtime so that the same chunk always gives the same bytes (its sha256 is stored).
"""

from __future__ import annotations

import gzip
import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = ["encode", "read_at", "read_scenarios", "relative_path"]


def relative_path(catalogue_id: str, index: int) -> str:
    """Path of chunk ``index`` of a catalogue, relative to the data dir."""
    return f"catalogues/{catalogue_id}/chunk_{index:06d}.jsonl.gz"


def encode(scenarios: Sequence[dict[str, Any] | None]) -> bytes:
    """The file content of a chunk's scenarios (deterministic bytes)."""
    lines = [json.dumps(s, separators=(",", ":")) for s in scenarios]
    return gzip.compress(("\n".join(lines) + "\n").encode(), compresslevel=6, mtime=0)


def read_scenarios(path: Path) -> Iterator[dict[str, Any] | None]:
    """The scenarios' JSON forms of a chunk file, in order (None: not built)."""
    with gzip.open(path, "rt", encoding="utf-8") as fh:
        for line in fh:
            if line.strip():
                data: dict[str, Any] | None = json.loads(line)
                yield data


def read_at(path: Path, position: int) -> dict[str, Any] | None:
    """The JSON form of the scenario at ``position`` (0-based) in a chunk file, or None."""
    for k, data in enumerate(read_scenarios(path)):
        if k == position:
            return data
    return None
