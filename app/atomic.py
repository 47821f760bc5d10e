"""Atomic file writes: a reader sees a file's old content or its new content, never a part.

The one helper of the service (the store's blobs and model cache, a job's stage and
progress files, the embedded parameter table, catalogue exports): write to a temporary
file beside the target, then rename it over the target (``os.replace``, atomic on POSIX
and Windows within one file system); on failure the temporary file is removed.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "write_atomic"]


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (its folder made if missing) for the caller to
    write; when the block ends without an exception it replaces ``path`` in one rename,
    otherwise it is removed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: Path, data: bytes | str, *, fsync: bool = True) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` atomically; ``fsync``: on disk before the
    rename (a crash then leaves the old or the new content, not an empty file)."""
    blob = data.encode("utf-8") if isinstance(data, str) else data
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(blob)
        fh.flush()
        if fsync:
            os.fsync(fh.fileno())
