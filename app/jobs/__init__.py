"""Catalogue jobs: chunked generation (sample → build → score), executors, resume.

Public surface:
- ``CatalogueSpec``, ``compute_chunk``, ``chunk_seed`` (``app.jobs.chunk``)
- ``make_executor`` and the executors (``app.jobs.executors``)
- ``CatalogueRunner`` (``app.jobs.runner``) and ``JobManager`` (``app.jobs.manager``)
"""

from app.jobs.chunk import CatalogueSpec, ChunkResult, chunk_seed, compute_chunk
from app.jobs.executors import (
    ChunkExecutor,
    DaskExecutor,
    InlineExecutor,
    LocalPoolExecutor,
    make_executor,
)
from app.jobs.runner import CatalogueRunner

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
