"""Where chunks run: inline, a local process pool (default) or a Dask cluster.

All executors have one method, ``run(spec, indices)``, that yields ``ChunkResult``s as
they finish (any order), keeping at most ``window`` chunks in flight so that a cancelled
job stops soon, and ``close()``. The local pool and Dask share one loop
(``FuturesExecutor``) on ``concurrent.futures``: Dask's ``Client.get_executor()`` gives
the same interface as a ``ProcessPoolExecutor``. The chunk function is
``app.jobs.chunk.compute_chunk``; the results are the same whichever executor runs it.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from app.jobs.fair import Share
from app.jobs.lifeline import pool_keeper_thread, quick_exit_worker

if TYPE_CHECKING:
    from app.jobs.chunk import CatalogueSpec, ChunkResult

log = logging.getLogger("scengen.jobs")

ChunkFn = Callable[["CatalogueSpec", int], "ChunkResult"]
#: seconds between two looks at a job's cancel flag while its chunks run
CANCEL_POLL = 0.25
T = TypeVar("T")


# This module imports no chunk machinery (the sampler, scikit-learn, numba) at its own
# import, so that a command can start the pool's workers first and import the rest while
# they start (issue 25 item 7). The workers are handed these two by reference and import
# ``app.jobs.chunk`` themselves.
def compute_chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
    """``app.jobs.chunk.compute_chunk`` (imported when first called)."""
    from app.jobs.chunk import compute_chunk as compute

    return compute(spec, index)


def warm_worker(hold: float = 0.0) -> int:
    """``app.jobs.chunk.warm_worker`` (imported when first called)."""
    from app.jobs.chunk import warm_worker as warm

    return warm(hold)


class Flag(Protocol):
    """Anything with ``is_set()`` (a threading.Event)."""

    def is_set(self) -> bool: ...


class ChunkExecutor(Protocol):
    name: str

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None, share: Share | None = None
            ) -> Iterator[ChunkResult]: ...

    def capacity(self) -> int: ...

    def map(self, fn: Callable[..., T], *args: Sequence[Any]) -> list[T]: ...

    def warm(self) -> Any: ...

    def futures_executor(self) -> Executor | None: ...

    def map_later(self, fn: Callable[..., T], *args: Sequence[Any]) -> Callable[[], list[T]]: ...

    def close(self) -> None: ...


class InlineExecutor:
    """Runs chunks one after the other in the calling thread (tests, debugging)."""

    name = "inline"

    def __init__(self, fn: ChunkFn = compute_chunk) -> None:
        self.fn = fn

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None, share: Share | None = None
            ) -> Iterator[ChunkResult]:
        """Each chunk in turn; with ``share``, each waits for the job's turn first."""
        for i in indices:
            if cancel is not None and cancel.is_set():
                return
            if share is None:
                yield self.fn(spec, i)
                continue
            if not share.acquire(cancel):
                return
            try:
                result = self.fn(spec, i)
            finally:
                share.release()
            yield result

    def capacity(self) -> int:
        """Chunks in flight at once: one."""
        return 1

    def map(self, fn: Callable[..., T], *args: Sequence[Any]) -> list[T]:
        """``fn`` over zipped ``args`` in this thread, results in order."""
        return [fn(*a) for a in zip(*args, strict=True)]

    def map_later(self, fn: Callable[..., T], *args: Sequence[Any]) -> Callable[[], list[T]]:
        """``map`` run when the returned function is called (nothing runs in between)."""
        return lambda: self.map(fn, *args)

    def futures_executor(self) -> None:
        """None: whoever asks runs its work in the calling thread."""
        return None

    def warm(self) -> None:
        """Nothing to start: chunks run in the calling thread."""

    def close(self) -> None:
        return None


class FuturesExecutor:
    """Runs chunks on any ``concurrent.futures.Executor``, at most ``window`` in flight.

    The one chunk loop of the service: the local process pool and Dask (through
    ``Client.get_executor()``, which returns standard futures) differ only in how the
    executor is made and how many chunks keep it busy.
    """

    name = "futures"

    def __init__(self, fn: ChunkFn = compute_chunk) -> None:
        self.fn = fn
        self._executor: Executor | None = None
        self._lock = threading.Lock()
        self._warm_thread: threading.Thread | None = None

    # what a subclass provides
    def _make(self) -> Executor:
        raise NotImplementedError

    def _window(self) -> int:
        return 2

    def _shutdown(self, executor: Executor) -> None:
        executor.shutdown(wait=True, cancel_futures=True)

    def _get(self) -> Executor:
        with self._lock:
            if self._executor is None:
                self._executor = self._make()
            return self._executor

    def capacity(self) -> int:
        """Chunks in flight at once that keep every worker busy (the window)."""
        return self._window()

    def run(self, spec: CatalogueSpec, indices: Iterable[int],
            cancel: Flag | None = None, share: Share | None = None
            ) -> Iterator[ChunkResult]:
        """Yield each chunk's result as it finishes (any order); stop submitting when
        ``cancel`` is set and cancel what has not started. With ``share`` (the job's
        handle on the service's ``FairSlots``) each chunk waits for the job's turn:
        blocking when the job has nothing in flight, else only if a slot is free now."""
        executor = self._get()
        window = self._window()
        pending: set[Future[ChunkResult]] = set()
        todo = iter(indices)
        exhausted = False
        try:
            while True:
                while not exhausted and len(pending) < window:
                    if cancel is not None and cancel.is_set():
                        exhausted = True
                        break
                    if share is not None and not (share.try_acquire() if pending
                                                  else share.acquire(cancel)):
                        exhausted = not pending  # cancelled while waiting
                        break
                    i = next(todo, None)
                    if i is None:
                        exhausted = True
                        if share is not None:
                            share.release()
                        break
                    try:
                        fut = executor.submit(self.fn, spec, i)
                    except BaseException:
                        if share is not None:
                            share.release()
                        raise
                    if share is not None:
                        share.release_when_done(fut)
                    pending.add(fut)
                if not pending:
                    return
                # a bounded wait: a cancel is seen while long chunks run
                done, _ = wait(pending, timeout=CANCEL_POLL, return_when=FIRST_COMPLETED)
                for fut in done:
                    pending.discard(fut)
                    yield fut.result()
                if cancel is not None and cancel.is_set():
                    return
        finally:
            for fut in pending:
                fut.cancel()

    def map(self, fn: Callable[..., T], *args: Sequence[Any]) -> list[T]:
        """``fn`` over zipped ``args`` on the executor's workers, results in order (what
        ``POST /scenarios`` uses to score its vectors on every core)."""
        return self.map_later(fn, *args)()

    def map_later(self, fn: Callable[..., T], *args: Sequence[Any]) -> Callable[[], list[T]]:
        """Submit ``fn`` over zipped ``args`` now; the returned function waits for the
        results (in order), so the caller can work while the workers do."""
        executor = self._get()
        futures = [executor.submit(fn, *a) for a in zip(*args, strict=True)]
        return lambda: [f.result() for f in futures]

    def futures_executor(self) -> Executor:
        """The underlying ``concurrent.futures`` executor (the local pool, or Dask's
        through ``Client.get_executor()``), for work that submits its own tasks, such as a
        campaign's parts (``sampler.campaign.evaluate(executor=...)``)."""
        return self._get()

    def warm(self) -> threading.Thread:
        """Start the workers and have each import the chunk machinery and load its compiled
        kernels (``app.jobs.chunk.warm_worker``) in the background, so the first catalogue
        or ``POST /scenarios`` after a start does not wait for that. Failures are logged
        only: a worker that could not warm up does so at its first chunk. Once per pool:
        a second call returns the first call's thread."""
        with self._lock:
            if self._warm_thread is not None:
                return self._warm_thread

        def run() -> None:
            try:
                self._warm_workers()
            except Exception as exc:
                log.warning("warming the %s workers failed: %r", self.name, exc)

        thread = threading.Thread(target=run, name=f"scengen-warm-{self.name}", daemon=True)
        with self._lock:
            self._warm_thread = thread
        thread.start()
        return thread

    def _warm_workers(self) -> None:
        executor = self._get()
        # the window is two tasks per worker: one warm-up each (an idle worker takes one)
        for fut in [executor.submit(warm_worker) for _ in range(max(1, self._window() // 2))]:
            fut.result()

    def close(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
            self._warm_thread = None
        if executor is not None:
            self._shutdown(executor)


#: seconds the start-up warm-up keeps trying to reach every local worker
WARM_DEADLINE = 900.0


class LocalPoolExecutor(FuturesExecutor):
    """A process pool on this machine (``spawn`` start method: safe under threads). Its
    workers die with this process however it ends (``app.jobs.lifeline``): they are
    started all at once from a keeper thread that lives as long as the pool."""

    name = "local"

    def __init__(self, workers: int, fn: ChunkFn = compute_chunk) -> None:
        if workers < 1:
            raise ValueError(f"local_workers: need at least 1 process, got {workers}")
        super().__init__(fn)
        self.workers = workers
        self._keeper_stop = threading.Event()

    def _make(self) -> Executor:
        log.info("starting a local process pool with %d workers", self.workers)
        pool = ProcessPoolExecutor(max_workers=self.workers,
                                   mp_context=multiprocessing.get_context("spawn"),
                                   initializer=quick_exit_worker, initargs=(os.getpid(),))

        def spawn_all() -> None:
            # one task per worker makes the pool start every worker now, from the keeper
            for fut in [pool.submit(os.getpid) for _ in range(self.workers)]:
                fut.exception()

        started = threading.Event()
        self._keeper_stop.clear()
        pool_keeper_thread(started, self._keeper_stop, spawn_all)
        started.wait()
        return pool

    def _shutdown(self, executor: Executor) -> None:
        super()._shutdown(executor)
        self._keeper_stop.set()

    def _window(self) -> int:
        return 2 * self.workers

    def _warm_workers(self) -> None:
        """Every worker, not only the first to be idle: rounds of one warm-up task per
        worker (each held a moment) until each pid has answered. Measured (issue 25 item 4):
        with a cold numba cache a worker still starting while the other took both tasks
        made the first request after the warm-up wait 33 s."""
        executor = self._get()
        seen: set[int] = set()
        deadline = time.monotonic() + WARM_DEADLINE
        while len(seen) < self.workers and time.monotonic() < deadline:
            futures = [executor.submit(warm_worker, 0.5) for _ in range(self.workers)]
            seen.update(f.result() for f in futures)


class DaskExecutor(FuturesExecutor):
    """Chunks on a dask.distributed cluster (a scheduler address or an existing Client),
    through the client's ``concurrent.futures`` executor."""

    name = "dask"

    def __init__(self, address: str | None = None, client: Any = None,
                 fn: ChunkFn = compute_chunk) -> None:
        from distributed import Client

        if client is None and not address:
            raise ValueError("dask_scheduler: need a scheduler address")
        super().__init__(fn)
        self._own = client is None
        make_client: Any = Client  # distributed ships no type hints
        self.client = client if client is not None else make_client(address, timeout="30s")

    def _make(self) -> Executor:
        executor: Executor = self.client.get_executor(pure=False)
        return executor

    def _window(self) -> int:
        try:
            workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
            threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        except Exception:  # the scheduler may be busy; any window works
            threads = 2
        return max(2, 2 * threads)

    def _shutdown(self, executor: Executor) -> None:
        executor.shutdown(wait=False)  # the client's, not the cluster's

    def _warm_workers(self) -> None:
        self._get()
        self.client.run(warm_worker)  # on every worker of the cluster

    def close(self) -> None:
        super().close()
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
