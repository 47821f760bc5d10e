"""Per-client quotas on jobs (issue 27 item 1), one mechanism for every job kind.

A client is the peer address of the request (``client_of``). Before a route stores a job
it calls ``jobs.quotas.hold(client_of(request), cost, settings)`` (``cost``: the job's
scenarios or runs; ``admit`` without the context manager): over
``client_jobs_limit`` jobs or ``client_queued_scenarios_limit`` scenarios queued and running
together, 429 ``TooManyRequests`` naming the setting, with ``Retry-After``. The returned
token is given to ``JobManager.submit(job_id, quota=token)``; the manager releases it when
the job ends (done, failed, cancelled, deleted). A job resumed at start-up has no client
and counts for nobody. Accounting is in memory: one service process.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from fastapi import Request

from app.errors import TooManyRequests
from app.settings import Settings

__all__ = ["ClientQuotas", "QuotaToken", "client_of"]


def client_of(request: Request) -> str:
    """The client a request counts for: its peer address."""
    return request.client.host if request.client is not None else "unknown"


@dataclass(frozen=True)
class QuotaToken:
    """What one admitted job holds of its client's quotas."""

    id: int
    client: str
    cost: int


class ClientQuotas:
    """The jobs and scenarios each client holds (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: dict[int, QuotaToken] = {}
        self._ids = itertools.count(1)

    def usage(self, client: str) -> tuple[int, int]:
        """(jobs, scenarios) the client holds."""
        with self._lock:
            mine = [t for t in self._held.values() if t.client == client]
        return len(mine), sum(t.cost for t in mine)

    def admit(self, client: str, cost: int, settings: Settings, *, field: str = "body.n",
              hint: str = "ask for fewer") -> QuotaToken:
        """Hold ``cost`` scenarios and one job for ``client``, or raise 429 naming ``field``
        (what the cost came from) and ending with ``hint``."""
        with self._lock:
            mine = [t for t in self._held.values() if t.client == client]
            jobs, queued = len(mine), sum(t.cost for t in mine)
            wait = settings.quota_retry_after
            if jobs + 1 > settings.client_jobs_limit:
                raise TooManyRequests(
                    f"you have {jobs} jobs queued or running, the most one client may have "
                    f"(SCENGEN_CLIENT_JOBS_LIMIT = {settings.client_jobs_limit}); try again "
                    "when one ends", retry_after=wait)
            if queued + cost > settings.client_queued_scenarios_limit:
                raise TooManyRequests(
                    f"{cost} more scenarios would make {queued + cost} queued or running for "
                    "you, over SCENGEN_CLIENT_QUEUED_SCENARIOS_LIMIT = "
                    f"{settings.client_queued_scenarios_limit}; try again when your jobs "
                    f"have progressed, or {hint}", retry_after=wait, field=field)
            token = QuotaToken(next(self._ids), client, int(cost))
            self._held[token.id] = token
            return token

    @contextmanager
    def hold(self, client: str, cost: int, settings: Settings, *, field: str = "body.n",
             hint: str = "ask for fewer") -> Iterator[QuotaToken]:
        """``admit``, released again if the block raises (the job was not stored)."""
        token = self.admit(client, cost, settings, field=field, hint=hint)
        try:
            yield token
        except BaseException:
            self.release(token)
            raise

    def release(self, token: QuotaToken | None) -> None:
        if token is not None:
            with self._lock:
                self._held.pop(token.id, None)
