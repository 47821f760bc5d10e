"""OpenSCENARIO 1.2 export (zip of .xosc files, one .xodr road, manifest.json)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from app.exports._common import ExportError, Row
from riskcore.scenario import ConcreteScenario

Item = tuple[int, ConcreteScenario, Mapping[str, Any], Row]


def write_xosc_zip(items: Iterator[Item], manifest: Mapping[str, Any], path: Path) -> None:
    raise ExportError("format 'xosc': not implemented yet")
