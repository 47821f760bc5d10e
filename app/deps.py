"""Shared request dependencies as ``Annotated`` aliases (one import for every router)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Query, Request
from sqlalchemy.orm import Session

from app.context import ServiceContext
from app.jobs.manager import JobManager
from app.schemas import SEED_MAX
from app.settings import Settings, get_settings
from sampler.region import constraint_grammar


def get_context(request: Request) -> ServiceContext:
    ctx: ServiceContext = request.app.state.ctx
    return ctx


def get_jobs(request: Request) -> JobManager:
    jobs: JobManager = request.app.state.jobs
    return jobs


ContextDep = Annotated[ServiceContext, Depends(get_context)]
JobsDep = Annotated[JobManager, Depends(get_jobs)]
SettingsDep = Annotated[Settings, Depends(get_settings)]


def get_session(ctx: ContextDep) -> Iterator[Session]:
    """A read-only session (every route that takes one only reads; writers open their own
    ``ctx.db.session()``)."""
    with ctx.db.read_session() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]


#: a region typed as one query string: constraints separated by ";" (default ttc<3)
#: constraints in one query string, separated by ';' (',' and '&' too; blanks dropped:
#: ``app.services.sampling.split_constraints``); the grammar is in the schema only, the
#: parser's 422 says what is wrong with a constraint
_ONE = constraint_grammar()
CONSTRAINTS_QUERY_PATTERN = rf"^\s*(?:{_ONE})?\s*(?:[;,&]\s*(?:{_ONE})?\s*)*$"
ConstraintsQuery = Annotated[str, Query(max_length=500, description="the region: "
                                        "constraints separated by ';', e.g. 'ttc<3' or "
                                        "'ttc<3; btn>0.7'",
                                        json_schema_extra={"pattern":
                                                           CONSTRAINTS_QUERY_PATTERN})]
#: a sampler seed in a query string
SeedQuery = Annotated[int, Query(ge=0, le=SEED_MAX)]
