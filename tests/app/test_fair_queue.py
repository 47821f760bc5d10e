"""The fair queue (issue 27 item 1): jobs of different clients share the workers chunk by
chunk instead of waiting behind each other; the rule that picks the next client, checked
by hand; the job manager's start order."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest

from app.jobs import CatalogueRunner, CatalogueSpec, ChunkResult, InlineExecutor
from app.jobs.fair import FairSlots, next_client
from app.jobs.manager import JobManager
from tests.app.test_jobs import _catalogue, _db, fake_chunk


def test_the_next_slot_goes_to_the_client_with_fewest_in_use_then_served_longest_ago() -> None:
    # fewest slots in use first, whatever the order of arrival
    assert next_client({"a": 1, "b": 1}, {"a": 2, "b": 1}, {"a": 1, "b": 9}, {}) == "b"
    # equal use: served longest ago (0 = never served) first
    assert next_client({"a": 1, "b": 1}, {"a": 1, "b": 1}, {"a": 5, "b": 3}, {}) == "b"
    assert next_client({"a": 1, "b": 1}, {}, {"a": 5}, {}) == "b"
    # equal in both: waiting longest first
    assert next_client({"a": 1, "b": 1}, {}, {}, {"a": 7, "b": 4}) == "b"
    # only waiting clients count
    assert next_client({"a": 0, "b": 1}, {"b": 3}, {}, {}) == "b"
    assert next_client({}, {"a": 1}, {}, {}) is None


def test_slots_bound_the_work_in_flight_and_skip_a_client_whose_turn_it_is_not() -> None:
    slots = FairSlots(2)
    assert slots.try_acquire("a") and slots.try_acquire("a")
    assert not slots.try_acquire("b")  # both slots in use
    got: list[str] = []
    waiter = threading.Thread(target=lambda: got.append("b" if slots.acquire("b") else "-"))
    waiter.start()
    deadline = time.monotonic() + 10
    while slots.waiting() != {"b": 1} and time.monotonic() < deadline:
        time.sleep(0.005)
    slots.release("a")
    waiter.join(10)
    assert got == ["b"] and slots.in_use() == {"a": 1, "b": 1}
    slots.release("b")
    # a free slot, and "b" (1 in use... now 0) waits for nobody: "a" may take it
    assert slots.try_acquire("a")
    with pytest.raises(RuntimeError):
        slots.release("c")
    cancelled = threading.Event()
    cancelled.set()
    assert slots.acquire("c", cancelled) is False  # full and cancelled: nothing taken
    assert slots.in_use() == {"a": 2}


class Interleaving:
    """Chunks and P(A) estimates of two catalogues that finish only once the other
    catalogue's client waits for a slot (while it has work left), so that each release
    finds the other waiting: the order of the work is then the scheduler's alone."""

    def __init__(self, sizes: dict[int, int]) -> None:
        self.sizes = sizes  # catalogue seed -> chunks
        self.done = {seed: 0 for seed in sizes}
        self.order: list[tuple[str, int]] = []
        self.manager: JobManager | None = None
        self.lock = threading.Lock()

    def _other_waits(self, seed: int) -> None:
        other = next(s for s in self.sizes if s != seed)
        client = CLIENTS[other]
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            assert self.manager is not None
            if self.done[other] >= self.sizes[other] + 1:  # estimate + chunks: all done
                return
            if self.manager.fair.waiting().get(client):
                return
            time.sleep(0.002)

    def chunk(self, spec: CatalogueSpec, index: int) -> ChunkResult:
        self._other_waits(spec.seed)
        with self.lock:
            self.order.append((CLIENTS[spec.seed], index))
            self.done[spec.seed] += 1
        return fake_chunk(spec, index)

    def region(self, spec: CatalogueSpec, stage: Any = None) -> dict[str, Any]:
        if spec.seed != FIRST:  # the first job's estimate runs before the second exists
            self._other_waits(spec.seed)
        with self.lock:
            self.order.append((CLIENTS[spec.seed], -1))
            self.done[spec.seed] += 1
        return {"estimate": 0.25, "ci": [0.2, 0.3]}


FIRST, SECOND = 1, 2
CLIENTS = {FIRST: "10.0.0.1", SECOND: "10.0.0.2"}


def test_two_clients_jobs_alternate_chunk_by_chunk(tmp_path: Path) -> None:
    """One worker slot; client 1's catalogue of 6 chunks starts first, client 2's of 3
    chunks arrives while the first is estimating P(A): the chunks alternate 1, 2, 1, 2 ...
    (a queue that runs jobs one after another computes all 6 of client 1's first)."""
    db = _db(tmp_path)
    _catalogue(db, "big", n=30, seed=FIRST)  # chunks of 5: 6 chunks
    _catalogue(db, "small", n=15, seed=SECOND)  # 3 chunks
    work = Interleaving({FIRST: 6, SECOND: 3})
    gate = threading.Event()
    first_region = work.region

    def held_region(spec: CatalogueSpec, stage: Any = None) -> dict[str, Any]:
        if spec.seed == FIRST:
            gate.wait(10)  # the second job is submitted while this one holds the slot
            work._other_waits(spec.seed)
        return first_region(spec, stage)

    runner = CatalogueRunner(db, tmp_path, InlineExecutor(work.chunk), region=held_region)
    manager = JobManager(runner)
    work.manager = manager
    assert manager.fair.slots == 1  # the inline executor: one chunk at a time
    manager.start(resume=False)
    try:
        manager.submit("big", client=CLIENTS[FIRST])
        deadline = time.monotonic() + 10
        while manager.fair.in_use() != {CLIENTS[FIRST]: 1} and time.monotonic() < deadline:
            time.sleep(0.002)
        manager.submit("small", client=CLIENTS[SECOND])
        gate.set()
        deadline = time.monotonic() + 60
        while not manager.idle() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert manager.idle()
    finally:
        manager.stop()
    a, b = CLIENTS[FIRST], CLIENTS[SECOND]
    assert work.order == [(a, -1), (b, -1), (a, 0), (b, 0), (a, 1), (b, 1), (a, 2), (b, 2),
                          (a, 3), (a, 4), (a, 5)]


def test_the_next_job_to_start_is_the_oldest_of_the_client_with_fewest_running(
        tmp_path: Path) -> None:
    """With one job running at a time: client 1 queues three jobs, client 2 one after
    them; client 2's starts second, not fourth."""
    db = _db(tmp_path)
    started: list[str] = []
    gate = threading.Event()

    def region(spec: CatalogueSpec, stage: Any = None) -> dict[str, Any]:
        gate.wait(10)
        return {"estimate": 0.25, "ci": [0.2, 0.3]}

    class Recording(CatalogueRunner):
        def run(self, catalogue_id: str, **kw: Any) -> str:
            started.append(catalogue_id)
            return super().run(catalogue_id, **kw)

    for cid in ("a1", "a2", "a3", "b1"):
        _catalogue(db, cid, n=5)
    manager = JobManager(Recording(db, tmp_path, InlineExecutor(fake_chunk), region=region),
                         running_limit=1)
    for cid in ("a1", "a2", "a3"):
        manager.submit(cid, client="a")
    manager.submit("b1", client="b")
    manager.start(resume=False)
    gate.set()
    deadline = time.monotonic() + 60
    while not manager.idle() and time.monotonic() < deadline:
        time.sleep(0.01)
    manager.stop()
    assert started == ["a1", "b1", "a2", "a3"]
