"""A fair share of the workers between clients (issue 27 item 1).

Jobs run side by side (``JobManager`` starts several); what they share is the executor's
capacity, counted in *slots*: one slot is one unit of work in flight (a catalogue chunk,
a part of an evaluation's chunk, a catalogue's P(A) estimate). A job asks for a slot
before it submits each unit and gives it back when the unit ends. When a slot is free it
goes to the waiting client with the fewest slots in use, ties to the client served
longest ago (then the one that has waited longest). So a client with one huge job and a
client with a small one alternate chunk by chunk instead of the small one waiting hours
behind the huge one; a client's several jobs share that client's turn.

``next_client`` is the rule alone (a pure function, tested by hand); ``FairSlots`` the
thread-safe bookkeeping; ``Share`` one job's handle on it; ``FairExecutor`` a
``concurrent.futures.Executor`` whose ``submit`` takes a slot first (the evaluations'
campaign submits its own parts).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Executor, Future
from contextlib import contextmanager
from typing import Any, Protocol, TypeVar

__all__ = ["FairExecutor", "FairSlots", "InlineFutures", "JobCancelled", "Share",
           "next_client"]

T = TypeVar("T")

#: seconds between two looks at a job's cancel flag while it waits for a slot
POLL = 0.2


class Flag(Protocol):
    def is_set(self) -> bool: ...


class JobCancelled(Exception):
    """The job was cancelled (or the service stops) while it waited for a slot."""


def next_client(waiting: Mapping[str, int], used: Mapping[str, int],
                served: Mapping[str, int], arrived: Mapping[str, int]) -> str | None:
    """Which waiting client gets the next free slot: fewest slots in use, then served
    longest ago (``served``: the tick of its last grant, 0 = never), then waiting longest
    (``arrived``: the tick its oldest wait began). None when nobody waits."""
    candidates = [c for c, k in waiting.items() if k > 0]
    if not candidates:
        return None
    return min(candidates, key=lambda c: (used.get(c, 0), served.get(c, 0),
                                          arrived.get(c, 0), c))


class FairSlots:
    """At most ``slots`` units of work in flight, handed out by ``next_client``."""

    def __init__(self, slots: int) -> None:
        if slots < 1:
            raise ValueError(f"slots: need at least 1, got {slots}")
        self.slots = slots
        self._cv = threading.Condition()
        self._used: dict[str, int] = {}
        self._waiting: dict[str, int] = {}
        self._served: dict[str, int] = {}
        self._arrived: dict[str, int] = {}
        self._ticks = itertools.count(1)
        #: (client) of every grant, in order (bounded: the last ``LOG`` grants)
        self.log: list[str] = []

    LOG = 10_000

    def in_use(self) -> dict[str, int]:
        with self._cv:
            return {c: k for c, k in self._used.items() if k}

    def waiting(self) -> dict[str, int]:
        with self._cv:
            return {c: k for c, k in self._waiting.items() if k}

    def _free(self) -> bool:
        return sum(self._used.values()) < self.slots

    def _grant(self, client: str) -> None:
        self._used[client] = self._used.get(client, 0) + 1
        self._served[client] = next(self._ticks)
        self.log.append(client)
        if len(self.log) > self.LOG:
            del self.log[: len(self.log) - self.LOG]

    def try_acquire(self, client: str) -> bool:
        """A slot now if one is free and no waiting client comes before ``client``."""
        with self._cv:
            if not self._free():
                return False
            first = next_client({**self._waiting, client: 1}, self._used, self._served,
                                {**self._arrived, client: next(self._ticks)})
            if first != client:
                return False
            self._grant(client)
            return True

    def acquire(self, client: str, cancel: Flag | None = None) -> bool:
        """Wait for ``client``'s turn and take a slot; False (nothing taken) when
        ``cancel`` is set first."""
        with self._cv:
            self._waiting[client] = self._waiting.get(client, 0) + 1
            if self._waiting[client] == 1:
                self._arrived[client] = next(self._ticks)
            try:
                while True:
                    if cancel is not None and cancel.is_set():
                        return False
                    if self._free() and next_client(self._waiting, self._used, self._served,
                                                    self._arrived) == client:
                        self._grant(client)
                        return True
                    self._cv.wait(POLL)
            finally:
                self._waiting[client] -= 1
                self._cv.notify_all()  # the next in line may be someone else now

    def release(self, client: str) -> None:
        with self._cv:
            if self._used.get(client, 0) <= 0:
                raise RuntimeError(f"release without a slot held by {client!r}")
            self._used[client] -= 1
            self._cv.notify_all()

    def share(self, client: str) -> Share:
        return Share(self, client)


class Share:
    """One job's handle: the client it counts for and the slots it holds."""

    def __init__(self, slots: FairSlots, client: str) -> None:
        self.slots = slots
        self.client = client

    def acquire(self, cancel: Flag | None = None) -> bool:
        return self.slots.acquire(self.client, cancel)

    def try_acquire(self) -> bool:
        return self.slots.try_acquire(self.client)

    def release(self) -> None:
        self.slots.release(self.client)

    @contextmanager
    def slot(self, cancel: Flag | None = None) -> Iterator[None]:
        """Hold one slot for the block (``JobCancelled`` if cancelled while waiting)."""
        if not self.acquire(cancel):
            raise JobCancelled()
        try:
            yield
        finally:
            self.release()

    def release_when_done(self, future: Future[Any]) -> None:
        future.add_done_callback(lambda _f: self.release())


class InlineFutures(Executor):
    """Runs each submitted call at once in the calling thread (a finished future)."""

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        future: Future[T] = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # the caller sees it from result(), as with a pool
            future.set_exception(exc)
        return future


class FairExecutor(Executor):
    """An executor whose ``submit`` first waits for the job's turn (``Share``; none:
    no waiting) and refuses to start anything once the job is cancelled
    (``JobCancelled``): the campaign of an evaluation submits its parts through it, so a
    cancelled evaluation stops after the parts in flight, not at the end of its chunk."""

    def __init__(self, inner: Executor, share: Share | None,
                 cancel: Flag | None = None) -> None:
        self.inner = inner
        self.share = share
        self.cancel = cancel

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        if self.cancel is not None and self.cancel.is_set():
            raise JobCancelled()
        if self.share is None:
            return self.inner.submit(fn, *args, **kwargs)
        if not self.share.acquire(self.cancel):
            raise JobCancelled()
        try:
            future = self.inner.submit(fn, *args, **kwargs)
        except BaseException:
            self.share.release()
            raise
        self.share.release_when_done(future)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Nothing: the inner executor belongs to the service."""
