"""The one owner of the catalogue chunk files: where they live, how they are written and read.

A chunk file holds the concrete scenarios of one chunk as gzip'd JSON lines (one
``scengen.concrete-scenario/1`` object per line, in index order; ``null`` for a vector the
builder refused, whose row carries the error), written with a fixed
gzip mtime so that the same chunk always gives the same bytes (its sha256 is stored).

Beside them, while a chunk is being computed, a worker on this machine keeps a progress
file (``progress_<index>``: how many of the chunk's scenarios are done) so that the status
and the CLI bar move per scenario, not per chunk; the runner removes it when the chunk is
stored. A worker that cannot write there (a Dask worker on another machine) reports nothing
and the progress moves per chunk.

The runner also keeps ``stage.json`` there while the job runs: what it is doing now
(estimating P(A), with the sampler's own stage and counts; sampling and scoring; refining
the model interval), so that the status says why the progress stays at 0 during a
P(A) estimate of half a minute.

A cancelled job (``DELETE``, the CLI's Ctrl-C) leaves a ``stop`` file there
(``request_stop``); the workers computing its chunks look for it (and for the folder
having been removed, which a deletion does) every quarter second (``stop_requested``) and
give their chunk up, so that a cancelled job stops within a moment instead of finishing
the chunks in flight. A worker on another machine sees neither and finishes its chunk.
"""

from __future__ import annotations

import contextlib
import gzip
import json
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from app.atomic import write_atomic

__all__ = ["clear_progress", "clear_stage", "clear_stop", "encode", "progress_dir", "read_at",
           "read_progress", "read_scenarios", "read_stage", "relative_path", "request_stop",
           "stop_requested", "write_progress", "write_stage"]

STAGE_FILE = "stage.json"
STOP_FILE = "stop"


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


def progress_dir(data_dir: Path, catalogue_id: str) -> Path:
    """Folder of a catalogue's chunk files and progress files."""
    return data_dir / "catalogues" / catalogue_id


def write_progress(folder: str | Path, index: int, done: int) -> None:
    """Record that ``done`` scenarios of chunk ``index`` are computed (best effort: a
    folder that cannot be written is skipped, and a folder that is gone is not made
    again: the catalogue was deleted)."""
    if Path(folder).is_dir():
        _write_atomic(Path(folder) / f"progress_{index:06d}", str(int(done)))


def request_stop(folder: Path) -> None:
    """Ask the workers computing the catalogue's chunks to give them up (when the folder
    exists: a queued job has none and nothing in flight)."""
    if folder.is_dir():
        _write_atomic(folder / STOP_FILE, "stop")


def clear_stop(folder: Path) -> None:
    """Forget a stop request (the job is run again)."""
    with contextlib.suppress(OSError):
        (folder / STOP_FILE).unlink()


def stop_requested(folder: str | Path, existed: bool) -> bool:
    """Whether the chunks of the catalogue whose folder this is should stop: it has a
    ``stop`` file, or it ``existed`` when the chunk started and is gone now (deleted)."""
    path = Path(folder)
    if (path / STOP_FILE).exists():
        return True
    return existed and not path.is_dir()


def read_progress(folder: Path) -> dict[int, int]:
    """Chunk index -> scenarios done, of the chunks with a progress file."""
    out: dict[int, int] = {}
    with contextlib.suppress(OSError):
        for path in folder.glob("progress_*"):
            with contextlib.suppress(OSError, ValueError):
                out[int(path.name.removeprefix("progress_"))] = int(path.read_text())
    return out


def write_stage(folder: str | Path, name: str, done: int | None = None,
                total: int | None = None) -> None:
    """Record the job's current stage (best effort, atomic: a reader sees the old or the
    new stage, never half of one)."""
    _write_atomic(Path(folder) / STAGE_FILE,
                  json.dumps({"name": name, "done": done, "total": total}))


def _write_atomic(path: Path, text: str) -> None:
    """``app.atomic.write_atomic`` (a reader sees the old or the new content), best effort:
    a folder that cannot be written is skipped; not synced (progress, rewritten often)."""
    with contextlib.suppress(OSError):
        write_atomic(path, text, fsync=False)


def read_stage(folder: Path) -> dict[str, Any] | None:
    """The stage last written (``{"name", "done", "total"}``), or None."""
    try:
        data = json.loads((Path(folder) / STAGE_FILE).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("name"), str) else None


def clear_stage(folder: Path) -> None:
    """Remove the stage file (the job ended or was interrupted)."""
    with contextlib.suppress(OSError):
        (Path(folder) / STAGE_FILE).unlink()


def clear_progress(folder: Path, index: int) -> None:
    """Remove chunk ``index``'s progress file (its chunk is stored)."""
    with contextlib.suppress(OSError):
        (folder / f"progress_{index:06d}").unlink()
