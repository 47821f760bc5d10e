"""Catalogue jobs: chunked generation (sample → build → score), executors, resume.

Public surface:
- ``CatalogueSpec``, ``compute_chunk``, ``chunk_seed`` (``app.jobs.chunk``)
- ``make_executor`` and the executors (``app.jobs.executors``)
- ``CatalogueRunner`` (``app.jobs.runner``) and ``JobManager`` (``app.jobs.manager``)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.jobs.chunk import CatalogueSpec, ChunkResult, chunk_seed, compute_chunk
    from app.jobs.executors import (
        ChunkExecutor,
        DaskExecutor,
        InlineExecutor,
        LocalPoolExecutor,
        make_executor,
    )
    from app.jobs.runner import CatalogueRunner

#: where each public name lives; imported at first use (PEP 562), so that
#: ``app.jobs.executors`` can start a pool before the chunk machinery (the sampler,
#: scikit-learn, numba: seconds) is imported (issue 25 item 7)
_WHERE = {
    "CatalogueSpec": "app.jobs.chunk", "ChunkResult": "app.jobs.chunk",
    "chunk_seed": "app.jobs.chunk", "compute_chunk": "app.jobs.chunk",
    "ChunkExecutor": "app.jobs.executors", "DaskExecutor": "app.jobs.executors",
    "InlineExecutor": "app.jobs.executors", "LocalPoolExecutor": "app.jobs.executors",
    "make_executor": "app.jobs.executors", "CatalogueRunner": "app.jobs.runner",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'app.jobs' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)

__all__ = [
    "CatalogueRunner",
    "CatalogueSpec",
    "ChunkExecutor",
    "ChunkResult",
    "DaskExecutor",
    "InlineExecutor",
    "LocalPoolExecutor",
    "chunk_seed",
    "compute_chunk",
    "make_executor",
]
