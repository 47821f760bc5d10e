"""One runner per job: whoever runs a catalogue job (the service's job manager, the CLI's
``catalogue create`` and ``resume``) holds an exclusive ``flock`` on the job's lock file,
``<data dir>/jobs/<id>.lock``, for as long as it runs it; the holder's pid is written in
the file. A second runner is refused (``JobBusy``) instead of running the same chunks
beside the first. The OS drops the lock when its holder ends, SIGKILL included, so a
killed runner leaves nothing that blocks the next one; a runner that ends normally
removes the file. The descriptor is close-on-exec (Python's default), so the pool's
workers, which are spawned (fork and exec), never hold it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

#: the folder of the data dir that holds the jobs' lock files
LOCK_DIR = "jobs"


class JobBusy(Exception):
    """The job is being run by another process (``pid``: 0 when it has not written it
    yet)."""

    def __init__(self, job_id: str, pid: int) -> None:
        who = f"pid {pid}" if pid else "pid unknown"
        super().__init__(f"{job_id} is being run by another process ({who})")
        self.job_id = job_id
        self.pid = pid


@dataclass(frozen=True)
class JobLock:
    path: Path
    fd: int


def lock_path(data_dir: Path, job_id: str) -> Path:
    return Path(data_dir) / LOCK_DIR / f"{job_id}.lock"


def acquire(data_dir: Path, job_id: str) -> JobLock:
    """Lock the job for this process, or ``JobBusy`` naming the holder's pid."""
    import fcntl

    path = lock_path(data_dir, job_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            text = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
            os.close(fd)
            raise JobBusy(job_id, int(text) if text.isdigit() else 0) from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        # the file was removed by the holder that just released it: lock the new one
        os.close(fd)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return JobLock(path, fd)


def check_free(data_dir: Path, job_id: str) -> None:
    """``JobBusy`` naming the holder's pid if another runner holds the job's lock now; takes
    nothing and creates nothing (a command checks this before it starts its workers). The
    answer holds only for that moment: a runner still takes the lock itself (``acquire``).
    A job without a lock file, or an id that is no file name, has no holder."""
    import fcntl

    if not job_id or "\0" in job_id or Path(job_id).name != job_id:
        return
    try:
        fd = os.open(lock_path(data_dir, job_id), os.O_RDONLY)
    except FileNotFoundError:  # a holder keeps its file until it has unlocked it
        return
    try:
        try:
            # shared: refused while a runner holds it, taken for an instant otherwise
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            text = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
            raise JobBusy(job_id, int(text) if text.isdigit() else 0) from None
    finally:
        os.close(fd)  # which unlocks


def release(lock: JobLock) -> None:
    """Remove the lock file (while still holding it: a runner waiting on the old file
    sees it gone and takes a new one) and unlock."""
    try:
        if os.stat(lock.path).st_ino == os.fstat(lock.fd).st_ino:
            os.unlink(lock.path)
    except FileNotFoundError:
        pass
    finally:
        os.close(lock.fd)
