"""Where chunks run: inline, a local process pool (default) or a Dask cluster.

All executors have one method, ``run(spec, indices)``, that yields ``ChunkResult``s as
they finish (any order), keeping at most ``window`` chunks in flight so that a cancelled
job stops soon, and ``close()``. The chunk function is ``app.jobs.chunk.compute_chunk``;
the results are the same whichever executor runs it.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Protocol

from app.jobs.chunk import CatalogueSpec, ChunkResult, compute_chunk

log = logging.getLogger("scengen.jobs")

ChunkFn = Callable[[CatalogueSpec, int], ChunkResult]


class Flag(Protocol):
    """Anything with ``is_set()`` (a threading.Event)."""

    def is_set(self) -> bool: ...


class ChunkExecutor(Protocol):
    name: str

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None) -> Iterator[ChunkResult]: ...

    def close(self) -> None: ...


class InlineExecutor:
    """Runs chunks one after the other in the calling thread (tests, debugging)."""

    name = "inline"

    def __init__(self, fn: ChunkFn = compute_chunk) -> None:
        self.fn = fn

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None) -> Iterator[ChunkResult]:
        for i in indices:
            if cancel is not None and cancel.is_set():
                return
            yield self.fn(spec, i)

    def close(self) -> None:
        return None


def _windowed(submit: Callable[[int], Any], wait_any: Callable[[set[Any]], set[Any]],
              result: Callable[[Any], ChunkResult], cancel_all: Callable[[set[Any]], None],
              indices: Iterable[int], window: int,
              cancel: Flag | None) -> Iterator[ChunkResult]:
    pending: set[Any] = set()
    todo = iter(indices)
    exhausted = False
    try:
        while True:
            while not exhausted and len(pending) < window:
                if cancel is not None and cancel.is_set():
                    exhausted = True
                    break
                try:
                    i = next(todo)
                except StopIteration:
                    exhausted = True
                    break
                pending.add(submit(i))
            if not pending:
                return
            done = wait_any(pending)
            for fut in done:
                pending.discard(fut)
                yield result(fut)
            if cancel is not None and cancel.is_set():
                return
    finally:
        if pending:
            cancel_all(pending)


class LocalPoolExecutor:
    """A process pool on this machine (``spawn`` start method: safe under threads)."""

    name = "local"

    def __init__(self, workers: int, fn: ChunkFn = compute_chunk) -> None:
        if workers < 1:
            raise ValueError(f"local_workers: need at least 1 process, got {workers}")
        self.workers = workers
        self.fn = fn
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def _get_pool(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._pool is None:
                log.info("starting a local process pool with %d workers", self.workers)
                self._pool = ProcessPoolExecutor(
                    max_workers=self.workers, mp_context=multiprocessing.get_context("spawn")
                )
            return self._pool

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None) -> Iterator[ChunkResult]:
        pool = self._get_pool()

        def wait_any(pending: set[Any]) -> set[Any]:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            return set(done)

        def result(fut: Any) -> ChunkResult:
            value: ChunkResult = fut.result()
            return value

        def cancel_all(pending: set[Any]) -> None:
            for fut in pending:
                fut.cancel()

        def submit(i: int) -> Future[ChunkResult]:
            return pool.submit(self.fn, spec, i)

        yield from _windowed(submit, wait_any, result, cancel_all, indices,
                             2 * self.workers, cancel)

    def close(self) -> None:
        with self._lock:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None


class DaskExecutor:
    """Chunks on a dask.distributed cluster: a scheduler address or an existing Client."""

    name = "dask"

    def __init__(self, address: str | None = None, client: Any = None,
                 fn: ChunkFn = compute_chunk) -> None:
        from distributed import Client

        if client is None and not address:
            raise ValueError("dask_scheduler: need a scheduler address")
        self._own = client is None
        self.client = client if client is not None else Client(address, timeout="30s")
        self.fn = fn

    def _window(self) -> int:
        try:
            workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
            threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        except Exception:  # the scheduler may be busy; any window works
            threads = 2
        return max(2, 2 * threads)

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None) -> Iterator[ChunkResult]:
        from distributed import wait as dask_wait

        def submit(i: int) -> Any:
            return self.client.submit(self.fn, spec, i, pure=False)

        def wait_any(pending: set[Any]) -> set[Any]:
            done = dask_wait(list(pending), return_when="FIRST_COMPLETED").done
            return set(done)

        def result(fut: Any) -> ChunkResult:
            value: ChunkResult = fut.result()
            return value

        def cancel_all(pending: set[Any]) -> None:
            self.client.cancel(list(pending))

        yield from _windowed(submit, wait_any, result, cancel_all, indices,
                             self._window(), cancel)

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(*, dask_scheduler: str | None, local_workers: int) -> ChunkExecutor:
    """Dask when a scheduler is configured, else the local pool (inline for 0 workers)."""
    if dask_scheduler:
        log.info("catalogue chunks run on the Dask scheduler at %s", dask_scheduler)
        return DaskExecutor(dask_scheduler)
    if local_workers == 0:
        return InlineExecutor()
    return LocalPoolExecutor(local_workers)
