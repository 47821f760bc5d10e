"""A catalogue's P(A) estimate (and the refinement of its model interval) runs on the
executor's workers, not in the job's thread of the service process (issue 27 follow-up:
eight small catalogues estimating at once in the service's threads held its GIL, /health
p99 915 ms under the load test). The stages still reach the listener (the CLI's bars),
and a job cancelled during an estimate in a worker stops the worker at its next stage."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from app.db import repository as repo
from app.jobs import CatalogueRunner, CatalogueSpec, InlineExecutor
from app.jobs.executors import LocalPoolExecutor
from tests.app.test_jobs import _catalogue, _db, fake_chunk

WORKER = "pool-worker"


class ChunksInlineWorkersInPool(InlineExecutor):
    """Chunks in the calling thread, and a thread pool as the workers' futures executor
    (what the local process pool and Dask give the runner)."""

    def __init__(self) -> None:
        super().__init__(fake_chunk)
        self.pool = ThreadPoolExecutor(1, thread_name_prefix=WORKER)

    def futures_executor(self) -> ThreadPoolExecutor:  # type: ignore[override]
        return self.pool

    def close(self) -> None:
        self.pool.shutdown(wait=True)


class Recorder:
    """A region function that records the thread it ran in and, between its stages,
    waits until the listener has heard the stage (so no poll can miss one)."""

    def __init__(self) -> None:
        self.threads: list[str] = []
        self.heard: dict[str, threading.Event] = {"pilot": threading.Event(),
                                                 "subset-is": threading.Event()}

    def __call__(self, spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
        self.threads.append(threading.current_thread().name)
        for name in self.heard:
            stage(name, 1, 2)
            assert self.heard[name].wait(60), f"the listener never heard {name}"
        return {"estimate": 0.25, "ci": [0.2, 0.3]}

    def listener(self, name: str, done: int, total: int) -> None:
        for stage_name, event in self.heard.items():
            if name == f"P(A): {stage_name}":
                event.set()


def test_the_estimate_runs_on_a_worker_and_its_stages_reach_the_listener(
        tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "w")
    region = Recorder()
    executor = ChunksInlineWorkersInPool()
    try:
        runner = CatalogueRunner(db, tmp_path, executor, region=region)
        assert runner.run("w", stage=region.listener) == "done"
    finally:
        executor.close()
    # before: the estimate ran in the job's own thread (MainThread here)
    assert len(region.threads) == 1 and region.threads[0].startswith(WORKER)
    assert all(e.is_set() for e in region.heard.values())
    with db.session() as s:
        assert (repo.get_catalogue(s, "w").p_region or {}).get("estimate") == 0.25


def test_the_refinement_runs_on_a_worker(tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "r")
    unresolved = {"estimate": 0.25, "model_interval": {"lower": 0.1, "upper": 0.4,
                                                       "lower_resolved": False}}
    threads: list[str] = []

    def refine(spec: CatalogueSpec, p_region: dict[str, Any]) -> dict[str, Any]:
        threads.append(threading.current_thread().name)
        return {**p_region, "refined": True}

    executor = ChunksInlineWorkersInPool()
    try:
        runner = CatalogueRunner(db, tmp_path, executor,
                                 region=lambda spec, stage: unresolved, refine=refine)
        assert runner.run("r") == "done"
    finally:
        executor.close()
    assert len(threads) == 1 and threads[0].startswith(WORKER)  # before: MainThread
    with db.session() as s:
        assert (repo.get_catalogue(s, "r").p_region or {}).get("refined") is True


def test_a_job_cancelled_during_an_estimate_on_a_worker_stops_the_worker(
        tmp_path: Path) -> None:
    db = _db(tmp_path)
    _catalogue(db, "c")
    cancel = threading.Event()
    stages: list[int] = []
    stopped = threading.Event()

    def slow_region(spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
        try:
            for k in range(200):
                stages.append(k)
                if k == 2:
                    cancel.set()
                stage("pilot", k, 200)
                threading.Event().wait(0.05)
        except BaseException:
            stopped.set()
            raise
        return {"estimate": 0.25, "ci": [0.2, 0.3]}

    executor = ChunksInlineWorkersInPool()
    try:
        runner = CatalogueRunner(db, tmp_path, executor, region=slow_region)
        assert runner.run("c", cancel=cancel) == "cancelled"
    finally:
        executor.close()  # waits for the worker
    assert stopped.is_set() and len(stages) < 200  # the worker saw the stop file
    with db.session() as s:
        assert repo.get_catalogue(s, "c").p_region is None  # estimated again on resume


def test_an_interrupt_while_waiting_for_the_worker_stops_the_worker(tmp_path: Path) -> None:
    """Ctrl-C in ``scengen catalogue create`` arrives in the thread that waits for the
    worker (here: raised by the stage listener): the worker's estimate stops too, at its
    next stage, instead of running to its end while the CLI waits to close the pool."""
    db = _db(tmp_path)
    _catalogue(db, "k")
    stages: list[int] = []
    stopped = threading.Event()

    def slow_region(spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
        try:
            for k in range(200):
                stages.append(k)
                stage("pilot", k, 200)
                threading.Event().wait(0.05)
        except BaseException:
            stopped.set()
            raise
        return {"estimate": 0.25, "ci": [0.2, 0.3]}

    def interrupt(name: str, done: int, total: int) -> None:
        if name == "P(A): pilot":
            raise KeyboardInterrupt

    executor = ChunksInlineWorkersInPool()
    try:
        runner = CatalogueRunner(db, tmp_path, executor, region=slow_region)
        with pytest.raises(KeyboardInterrupt):
            runner.run("k", stage=interrupt)
    finally:
        executor.close()  # waits for the worker
    assert stopped.is_set() and len(stages) < 200  # before: all 200 stages ran


def pid_region(spec: CatalogueSpec, stage: Any) -> dict[str, Any]:
    """A region function for a real worker process: says where it ran."""
    stage("pilot", 0, 1)
    return {"estimate": 0.25, "pid": os.getpid()}


@pytest.mark.slow
def test_in_the_service_the_estimate_runs_in_another_process(tmp_path: Path) -> None:
    """With the local process pool (the service's default) the estimate is sent to a
    worker process: the functions and spec travel by pickling under ``spawn``."""
    db = _db(tmp_path)
    _catalogue(db, "p")
    executor = LocalPoolExecutor(1, fn=fake_chunk)
    try:
        runner = CatalogueRunner(db, tmp_path, executor, region=pid_region)
        assert runner.run("p") == "done"
    finally:
        executor.close()
    with db.session() as s:
        pid = (repo.get_catalogue(s, "p").p_region or {}).get("pid")
    assert isinstance(pid, int) and pid != os.getpid()
