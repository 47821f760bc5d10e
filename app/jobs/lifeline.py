"""Pool workers that die with their parent (the service's catalogue pool and
:func:`lifeline_pool`, the pool ``scengen sample --score --workers N`` scores on).

A ``ProcessPoolExecutor``'s workers outlive a parent that is SIGKILLed (no clean shutdown
runs): they are reparented to PID 1 and keep their memory. ``die_with_parent`` is a pool
*initializer* that prevents it::

    ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn"),
                        initializer=die_with_parent, initargs=(os.getpid(),))

Two mechanisms, so that it holds wherever the worker runs:

* Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (through ctypes), so the kernel kills the
  worker at once when its parent goes away. The kernel ties this to the parent *thread*
  that started the worker: start pools from a thread that lives as long as the pool
  (``pool_keeper_thread`` below does that for the local executor).
* Everywhere: a daemon thread in the worker that checks every ``poll`` seconds whether
  its parent process is still the one it was started by (``os.getppid()`` changes when the
  parent dies and the worker is reparented) and ends the worker if not.

When every worker is gone, multiprocessing's resource tracker sees its pipe close and ends
too, so nothing of the pool is left.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _arm_parent_death_signal() -> bool:
    """Ask the kernel to SIGKILL this process when its parent dies (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return int(libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)) == 0
    except (OSError, AttributeError):  # no libc / no prctl: the watcher still works
        return False


def _watch_parent(parent_pid: int, poll: float) -> None:
    stop = threading.Event()
    while not stop.wait(poll):
        if os.getppid() != parent_pid:
            os._exit(1)  # no clean-up to run: the work belonged to the dead parent


def die_with_parent(parent_pid: int | None = None, poll: float = 0.5) -> None:
    """Pool initializer: end this worker when the process ``parent_pid`` (default: the
    current parent) ends, however it ends."""
    parent = os.getppid() if parent_pid is None else parent_pid
    _arm_parent_death_signal()
    if os.getppid() != parent:  # the parent died before the signal was armed
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent, poll), name="parent-watch",
                     daemon=True).start()


def _skip_finalization() -> None:
    """atexit handler of a pool worker: flush what it wrote, then end the process without
    the interpreter's module teardown (numba, scikit-learn, pandas: about 0.3 s per
    worker that ``shutdown(wait=True)`` waited for: issue 25 item 7). Runs after the
    handlers registered later (atexit is last in, first out) and after multiprocessing's
    own exit function; the worker's results went to the parent before."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(0)


def quick_exit_worker(parent_pid: int | None = None, poll: float = 0.5) -> None:
    """Pool initializer: ``die_with_parent`` and, at a clean shutdown, end without the
    interpreter's teardown (``_skip_finalization``)."""
    die_with_parent(parent_pid, poll)
    atexit.register(_skip_finalization)


def pool_keeper_thread(start: threading.Event, stop: threading.Event,
                       spawn: Callable[[], object]) -> threading.Thread:
    """A daemon thread that calls ``spawn()`` (which starts the pool's workers), sets
    ``start`` and then lives until ``stop`` is set: the workers' parent thread lives as
    long as the pool, as PR_SET_PDEATHSIG needs."""

    def keep() -> None:
        try:
            spawn()
        finally:
            start.set()
        stop.wait()

    thread = threading.Thread(target=keep, name="scengen-pool-keeper", daemon=True)
    thread.start()
    return thread


@contextlib.contextmanager
def lifeline_pool(n_workers: int, mp_context: str = "spawn") -> Iterator[Executor | None]:
    """A process pool of ``n_workers`` whose workers die with this process however it ends
    (None for one worker: run in this process). ``spawn`` is safe anywhere, including in a
    threaded server, but each worker re-imports the packages (seconds); ``fork`` starts at
    once and suits a single-threaded command-line process on POSIX."""
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        raise ValueError(f"n_workers: expected an integer >= 1, got {n_workers!r}")
    if mp_context not in multiprocessing.get_all_start_methods():
        raise ValueError(f"mp_context: {mp_context!r} is not available here; valid: "
                         f"{', '.join(multiprocessing.get_all_start_methods())}")
    if n_workers == 1:
        yield None
        return
    with ProcessPoolExecutor(max_workers=n_workers,
                             mp_context=multiprocessing.get_context(mp_context),
                             initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
        yield pool
