"""A time budget for synchronous requests (issue 27 item 3).

A request may hold a worker thread for at most ``sync_budget_seconds`` (SCENGEN_SYNC_
BUDGET_SECONDS, default 10 s) of sampling or estimating; past that it is refused with a
422 that says how to get the same work as a job (``POST /catalogues``) or a cheaper
request. And a client that has gone away stops its work: nothing it started is stored.

``BudgetGuard`` (ASGI middleware) gives every HTTP request a ``Budget`` in a context
variable; Starlette runs a synchronous route in a worker thread with a copy of that
context, so the sampler's progress callbacks (``app.domain.sampling`` wraps each one in
``checked``) and the last step before something is stored (``check``) see the request's
budget without any parameter passed around. Work outside a request (jobs, the CLI) has
no budget. The checks sit where the sampler reports progress: the estimators report every
fraction of a second (``benchmarks/bench_regions.py`` lists the gaps), so a refusal comes
within about half a second of the budget.
"""

from __future__ import annotations

import contextlib
import contextvars
import time
from collections.abc import Awaitable, Callable, Iterator, MutableMapping
from dataclasses import dataclass, field
from typing import Any

import anyio
import anyio.from_thread

from app.errors import InvalidInput, ServiceError
from app.settings import Settings

__all__ = ["BUDGET", "Budget", "BudgetGuard", "CheckDone", "ClientGone", "OverBudget", "check",
           "check_client", "checked", "limited", "precheck"]

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: how to get work that does not fit the budget
AS_A_JOB = ("ask for it as a job: POST /catalogues with the same model and constraints "
            "(its status carries P(A), its intervals and the rates; scengen catalogue "
            "create on the command line), or narrow the request (fewer samples, a less "
            "rare region)")


class OverBudget(InvalidInput):
    """The request's work would take longer than the synchronous budget (422)."""


class CheckDone(OverBudget):
    """A check's work (``precheck``) reached a stage past what it checks: it stops there."""


class ClientGone(ServiceError):
    """The client closed the connection: its work stops, nothing is stored."""

    status = 499


@dataclass
class Budget:
    seconds: float
    started: float = field(default_factory=lambda: time.monotonic())
    #: asks whether the client has gone (from a worker thread); None: never
    gone: Callable[[], bool] | None = None
    what: str = "this request"
    #: the stages the work may report (``precheck``); a report of any other stage stops it
    #: with ``CheckDone``. None: any stage
    stages: frozenset[str] | None = None

    def left(self) -> float:
        return self.seconds - (time.monotonic() - self.started)

    def check_client(self) -> None:
        """Raise ``ClientGone`` when the client has closed the connection."""
        if self.gone is not None and self.gone():
            raise ClientGone("the client closed the connection; the work was stopped and "
                             "nothing was stored")

    def check(self, stage: str | None = None) -> None:
        """Raise ``ClientGone`` or ``OverBudget`` when the work should stop (``CheckDone``
        when it reports a ``stage`` outside ``stages``)."""
        self.check_client()
        if stage is not None and self.stages is not None and stage not in self.stages:
            raise CheckDone(f"{self.what}: the check ends where stage {stage!r} starts")
        if self.left() < 0:
            raise OverBudget(
                f"{self.what} takes longer than the synchronous budget of {self.seconds:g} s "
                f"(SCENGEN_SYNC_BUDGET_SECONDS), so it was stopped; {AS_A_JOB}")


BUDGET: contextvars.ContextVar[Budget | None] = contextvars.ContextVar("scengen_budget",
                                                                      default=None)


def check() -> None:
    """Check the current request's budget (nothing outside a request)."""
    budget = BUDGET.get()
    if budget is not None:
        budget.check()


def check_client() -> None:
    """Raise ``ClientGone`` when the current request's client has gone (work that has no
    cheaper form, such as a model fit, is not refused for its time, only for that)."""
    budget = BUDGET.get()
    if budget is not None:
        budget.check_client()


@contextlib.contextmanager
def limited(seconds: float, what: str) -> Iterator[Budget | None]:
    """A budget of ``seconds`` for the work of the block outside a request (the CLI's
    ``--budget``): the same checks as a request's, ``OverBudget`` past it; 0: no limit."""
    budget = Budget(seconds, what=what) if seconds > 0 else None
    token = BUDGET.set(budget)
    try:
        yield budget
    finally:
        BUDGET.reset(token)


#: the stages of ``domain.estimate_region`` that an empty-region check runs: the pilot
#: (plain Monte Carlo up to its fixed number of draws, ``PRegionEstimator.pilot_max``, or
#: ``pilot_max_costly`` for a criticality region) and, when it found nothing, the broadened
#: search (a fixed number of draws too), which ends an empty region with its bound. The
#: estimate's next stage (subset simulation, subset-is, the extended pilot's probe, MCMC)
#: means the region has hits or needs the rare-event methods: the check stops there and
#: leaves the region to the job.
PRECHECK_STAGES = frozenset({"pilot"})


def precheck(work: Callable[[], object],
             stages: frozenset[str] = PRECHECK_STAGES) -> None:
    """Run ``work`` (a quick check before a job is stored, e.g. that its region is not
    empty) until it reports a stage outside ``stages``; work that gets there is left to
    the job, which fails with the same message if the check would have. The check is
    bounded by work (a fixed number of draws: the same verdict on any machine for the same
    model, region and seed), not by time; the request's time budget
    (SCENGEN_SYNC_BUDGET_SECONDS, 10 s; the empty-region check takes about 2 s on a quiet
    machine) is only a safety cap: past it the work is also left to the job."""
    outer = BUDGET.get()
    if outer is None:
        work()
        return
    inner = Budget(max(outer.left(), 0.0), gone=outer.gone, what=outer.what,
                   stages=stages)
    token = BUDGET.set(inner)
    try:
        work()
    except OverBudget:
        pass
    finally:
        BUDGET.reset(token)


def checked(progress: Callable[[str, int, int], None] | None
            ) -> Callable[[str, int, int], None] | None:
    """``progress`` with the request's budget checked at each call (``progress`` itself
    when there is no budget)."""
    budget = BUDGET.get()
    if budget is None:
        return progress

    def call(name: str, done: int, total: int) -> None:
        budget.check(name)
        if progress is not None:
            progress(name, done, total)

    return call


class BudgetGuard:
    """Gives each HTTP request its ``Budget`` (``settings().sync_budget_seconds``)."""

    def __init__(self, app: ASGIApp, settings: Callable[[], Settings]) -> None:
        self.app = app
        self.settings = settings

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = dict(scope.get("headers", []))
        no_body = (headers.get(b"content-length", b"0").strip() in (b"", b"0")
                   and b"transfer-encoding" not in headers)
        # a request without a body: the route never reads it, so polling may start at once
        state = {"body_done": no_body, "gone": False}

        async def tracked() -> Message:
            msg = await receive()
            if msg["type"] == "http.request" and not msg.get("more_body", False):
                state["body_done"] = True
            elif msg["type"] == "http.disconnect":
                state["gone"] = True
            return msg

        async def poll() -> bool:
            # once the body is read nobody else waits on receive() during the route: a
            # receive that is cancelled at once sees a disconnect that has arrived
            if state["gone"] or not state["body_done"]:
                return bool(state["gone"])
            msg: Message = {}
            with anyio.CancelScope() as scope_:
                scope_.cancel()
                msg = await receive()
            if msg.get("type") == "http.disconnect":
                state["gone"] = True
            return bool(state["gone"])

        def gone() -> bool:
            try:
                return bool(anyio.from_thread.run(poll))
            except RuntimeError:  # not in a worker thread of this event loop
                return bool(state["gone"])

        what = f"{scope.get('method', 'GET')} {scope.get('path', '')}"
        token = BUDGET.set(Budget(float(self.settings().sync_budget_seconds), gone=gone,
                                  what=what))
        try:
            await self.app(scope, tracked, send)
        finally:
            BUDGET.reset(token)
