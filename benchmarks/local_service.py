"""The service run in a subprocess on a free loopback port, for the benchmarks that talk to
it over HTTP (bench_load.py, bench_service.py, bench_first_request.py), and what they print
beside their figures (the load average, percentiles).

Not a benchmark itself (``make bench`` runs ``bench_*.py`` only); a benchmark run as
``python benchmarks/bench_x.py`` finds it next to itself.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import IO

import httpx

ROOT = Path(__file__).resolve().parents[1]


def load() -> str:
    """The machine's load averages (1, 5, 15 min) and core count, to print with a figure."""
    try:
        avg = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        avg = "n/a"
    return f"load {avg} on {os.cpu_count()} cores"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def service_env(data_dir: Path, env_extra: dict[str, str]) -> dict[str, str]:
    """This process's environment without any ``SCENGEN_`` variable, then the store in
    ``data_dir`` and ``env_extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SCENGEN_")}
    env.update({"SCENGEN_DATA_DIR": str(data_dir), **env_extra})
    return env


def stop_group(proc: subprocess.Popen[bytes], timeout: float) -> None:
    """SIGTERM to the process group ``proc`` leads (started with ``start_new_session``),
    SIGKILL if it has not ended after ``timeout`` s."""
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


class Server:
    """``uvicorn app.main:app`` in a subprocess on a free loopback port, its output
    appended to ``log``."""

    def __init__(self, data_dir: Path, env_extra: dict[str, str], log: Path) -> None:
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self._log: IO[bytes] = open(log, "ab")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "app.main:app", "--host", "127.0.0.1",
             "--port", str(self.port), "--log-level", "warning"],
            cwd=ROOT, env=service_env(data_dir, env_extra), stdout=self._log,
            stderr=self._log, start_new_session=True)

    def wait(self, timeout: float = 900, *, ready: bool = False) -> None:
        """Until ``/health`` answers 200 (``ready``: with ``status`` ``ok``, the start-up
        warm-up done); SystemExit when uvicorn exits or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise SystemExit(f"uvicorn exited with {self.proc.returncode}; see the log")
            try:
                r = httpx.get(f"{self.base}/health", timeout=5)
                if r.status_code == 200 and (not ready or r.json().get("status") == "ok"):
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.5)
        raise SystemExit("uvicorn did not come up")

    def stop(self) -> None:
        stop_group(self.proc, 120)
        self._log.close()


def percentile(values: list[float], p: float) -> float:
    """The p-quantile of ``values``, linear between order statistics (NaN when empty)."""
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    pos = p * (len(ordered) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (pos - lo)
