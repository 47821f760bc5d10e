"""JSONL export: a manifest line, then one full concrete scenario plus summary per line."""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from app.exports._common import ExportError, Row, decode_nonfinite, dumps, jsonable
from riskcore import ConcreteScenario, ScenarioError

MANIFEST_KIND = "manifest"
SCENARIO_KIND = "scenario"


def write_jsonl(
    items: Iterator[tuple[int, ConcreteScenario, Mapping[str, Any], Row]],
    manifest: Mapping[str, Any],
    path: Path,
) -> None:
    """Write line 1 ``{"kind": "manifest", ...}`` and one ``{"kind": "scenario"...}`` line
    per item, each flushed as it comes (UTF-8, ``\\n`` line ends)."""
    with path.open("w", encoding="utf-8", newline="\n") as fh:
        fh.write(dumps({"kind": MANIFEST_KIND, "manifest": dict(manifest)}) + "\n")
        for index, scenario, summary, _row in items:
            line = {
                "kind": SCENARIO_KIND,
                "index": index,
                "scenario": scenario.to_dict(),
                "summary": jsonable(summary, f"item {index}: summary"),
            }
            try:
                text = dumps(line)
            except (TypeError, ValueError) as exc:
                raise ExportError(f"item {index}: cannot be written as JSON ({exc})") from None
            fh.write(text + "\n")


def _parse(line: str, path: Path, lineno: int) -> dict[str, Any]:
    try:
        data = json.loads(line)
    except json.JSONDecodeError as exc:
        raise ExportError(f"{path}:{lineno}: not valid JSON ({exc.msg})") from None
    if not isinstance(data, dict) or "kind" not in data:
        raise ExportError(f"{path}:{lineno}: expected an object with a 'kind' field")
    return data


def read_manifest(path: Path) -> dict[str, Any]:
    with path.open(encoding="utf-8") as fh:
        first = fh.readline()
    if not first:
        raise ExportError(f"{path}: empty file, expected a scengen JSONL export")
    data = _parse(first, path, 1)
    if data["kind"] != MANIFEST_KIND or not isinstance(data.get("manifest"), dict):
        raise ExportError(f"{path}:1: expected the manifest line of a scengen JSONL export")
    manifest: dict[str, Any] = decode_nonfinite(data["manifest"])
    return manifest


def read_items(path: Path) -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
    read_manifest(path)
    with path.open(encoding="utf-8") as fh:
        fh.readline()
        for lineno, line in enumerate(fh, start=2):
            if not line.strip():
                continue
            data = _parse(line, path, lineno)
            if data["kind"] != SCENARIO_KIND:
                raise ExportError(f"{path}:{lineno}: unexpected kind {data['kind']!r}")
            try:
                scenario = ConcreteScenario.from_dict(data.get("scenario"))
            except ScenarioError as exc:
                raise ExportError(f"{path}:{lineno}: {exc}") from None
            summary = data.get("summary")
            if not isinstance(summary, dict):
                raise ExportError(f"{path}:{lineno}: summary: expected an object")
            yield scenario, decode_nonfinite(summary)
