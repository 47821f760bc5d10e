"""A file made on request and sent as the response (the catalogue and evaluation exports):
written in a fresh folder under ``<data_dir>/tmp``, removed after it has been sent, or at
once when writing it fails."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from fastapi import BackgroundTasks
from fastapi.responses import FileResponse

__all__ = ["file_response"]


def file_response(data_dir: Path, background: BackgroundTasks, filename: str,
                  media_type: str, write: Callable[[Path], object]) -> FileResponse:
    """``write(path)`` makes the file ``filename``; the response sends it."""
    tmp_root = data_dir / "tmp"
    tmp_root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="export-", dir=tmp_root))
    out = tmp / filename
    try:
        write(out)
    except BaseException:
        _rmtree(tmp)
        raise
    background.add_task(_rmtree, tmp)
    return FileResponse(out, media_type=media_type, filename=out.name)


def _rmtree(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)
