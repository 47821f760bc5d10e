"""The service's errors and the one JSON shape every error response has.

Exception hierarchy::

    ServiceError                  base: status 500 unless a subclass says otherwise
    ├── NotFound                  404  an unknown id
    ├── InvalidInput              422  a value the domain rejects (names the field)
    ├── PayloadTooLarge           413  an upload over the size limit
    ├── Conflict                  409  the resource is not in a state that allows it
    └── ServiceUnavailable        503  the service cannot answer yet (no default model)

The domain packages' own errors reach the client through the same body: any
``riskcore.FieldError`` -- the one tree drawn in riskcore/errors.py: ``sampler.SamplerError``
(``ConstraintError``, ``EmptyRegionError``, ``ModelError``, ...), ``RiskcoreError``,
``datasets.DatasetError``, ``app.exports.ExportError`` -- that a route does not catch maps
to the status in ``DOMAIN_STATUS`` (422 unless listed), and its structured ``field``
attribute (not its message) names the field, under ``body.``. Every other exception,
a ``ValueError`` from numpy, scipy or scikit-learn included, is our bug: 500, trace logged.

Every error body is ``{"error": {"status": <int>, "message": <str>, "field": <str|null>}}``;
``field`` is a dotted path such as ``body.n`` or ``query.format`` when one field is to blame.
"""

from __future__ import annotations

import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from riskcore import FieldError
from sampler import NotFittedError

log = logging.getLogger("scengen.app")


class ServiceError(Exception):
    """Base of the service's errors. ``status`` is the HTTP status it maps to."""

    status: int = 500

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.field = field


class NotFound(ServiceError, LookupError):
    status = 404


class InvalidInput(ServiceError, ValueError):
    status = 422


class PayloadTooLarge(ServiceError, ValueError):
    status = 413


class Conflict(ServiceError, ValueError):
    status = 409


class TooManyRequests(ServiceError):
    """A client over one of its quotas (429); ``Retry-After`` says when to try again."""

    status = 429

    def __init__(self, message: str, *, retry_after: int, field: str | None = None) -> None:
        super().__init__(message, field=field)
        self.headers = {"Retry-After": str(int(retry_after))}


class ServiceUnavailable(ServiceError):
    status = 503


#: an absolute file path (two or more segments) at the start or after a space/quote/bracket
_ABS_PATH = re.compile(r"""(?<![\w.:/])(?:/[\w.@+~-]+){2,}/?""")
#: a token long enough to be a pasted blob rather than a word
_LONG_TOKEN = re.compile(r"\S{121,}")
MESSAGE_MAX = 2000


def clean_message(message: str) -> str:
    """What may be shown to a client: no absolute server paths (only the file name stays),
    no 10 MB ids echoed back (long tokens are cut), at most MESSAGE_MAX characters."""
    text = _ABS_PATH.sub(lambda m: m.group(0).rstrip("/").rsplit("/", 1)[-1], message)
    text = _LONG_TOKEN.sub(lambda m: m.group(0)[:60] + "…", text)
    return text if len(text) <= MESSAGE_MAX else text[:MESSAGE_MAX] + "…"


def error_body(status: int, message: str, field: str | None = None) -> dict[str, Any]:
    shown = None if field is None else (field if len(field) <= 200 else field[:200] + "…")
    return {"error": {"status": status, "message": clean_message(message), "field": shown}}


def _response(status: int, message: str, field: str | None = None,
              headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse(error_body(status, message, field), status_code=status, headers=headers)


def _loc_to_field(loc: tuple[int | str, ...] | list[int | str]) -> str:
    return ".".join(str(p) for p in loc)


async def _service_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ServiceError)
    if exc.status == 499:  # app.budget.ClientGone: nobody reads the answer
        log.warning("%s %s: the client has gone; its work was stopped", request.method,
                 request.url.path)
    return _response(exc.status, exc.message, exc.field, getattr(exc, "headers", None))


#: HTTP status of a domain error class (the first match in the class's MRO; else 422)
DOMAIN_STATUS: dict[type[Exception], int] = {NotFittedError: 409}

#: the domain's errors: the one tree under ``riskcore.FieldError`` (riskcore/errors.py draws it);
#: any other exception, a library's ``ValueError`` included, is a 500 with a logged trace
DOMAIN_ERRORS: tuple[type[Exception], ...] = (FieldError,)


def domain_status(exc: Exception) -> int:
    """The HTTP status of a domain error (``DOMAIN_STATUS``, by class; else 422)."""
    for cls in type(exc).__mro__:
        if cls in DOMAIN_STATUS:
            return DOMAIN_STATUS[cls]
    return 422


def domain_field(exc: Exception, prefix: str = "body") -> str | None:
    """The request field a domain error blames: its ``field`` attribute under ``prefix``."""
    field = getattr(exc, "field", None)
    if field is None:
        return None
    return f"{prefix}.{field}" if prefix else str(field)


async def _domain_error(request: Request, exc: Exception) -> JSONResponse:
    return _response(domain_status(exc), str(exc), domain_field(exc))


async def _validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    errors = list(exc.errors())
    if not errors:
        return _response(422, "invalid request")
    first = errors[0]
    if first.get("type") == "json_invalid":  # the body is not JSON: nothing to validate
        loc = first.get("loc", ())
        at = f" at character {loc[1]}" if len(loc) > 1 and isinstance(loc[1], int) else ""
        why = (first.get("ctx") or {}).get("error") or "JSON decode error"
        return _response(400, f"body: could not be parsed as JSON{at}: {why}", "body")
    field = _loc_to_field(first.get("loc", ()))
    parts = []
    for err in errors[:5]:
        parts.append(f"{_loc_to_field(err.get('loc', ()))}: {err.get('msg', 'invalid')}")
    more = f" (and {len(errors) - 5} more)" if len(errors) > 5 else ""
    return _response(422, "; ".join(parts) + more, field)


def _allowed_methods(request: Request) -> str:
    """Every method some route of the app answers on this path (Starlette's 405 names only
    the first matching route's)."""
    methods = []
    for method in ("DELETE", "GET", "PATCH", "POST", "PUT"):
        scope = {**request.scope, "method": method}
        if any(route.matches(scope)[0] == Match.FULL for route in request.app.router.routes):
            methods.append(method)
    return ", ".join(methods)


async def _http_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    headers = dict(exc.headers) if exc.headers else None
    if exc.status_code == 405:
        headers = {**(headers or {}), "Allow": _allowed_methods(request)}
    if exc.status_code == 400:
        # the framework could not read the body (FastAPI's "There was an error parsing the
        # body", Starlette's "Missing boundary in multipart."): say what and why
        kind = request.headers.get("content-type", "no content type").split(";")[0]
        cause = exc.__cause__ or exc.__context__
        why = (f"{type(cause).__name__}: {cause}" if cause is not None
               and str(exc.detail) == "There was an error parsing the body" else exc.detail)
        return _response(400, f"body: could not be parsed as {kind}: {why}"[:300], "body",
                         headers)
    return _response(exc.status_code, str(exc.detail), None, headers)


async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
    log.exception("unexpected error on %s %s", request.method, request.url.path)
    return _response(500, f"internal error: {type(exc).__name__}")


def install_error_handlers(app: FastAPI) -> None:
    """Map every error to the one body shape (see the module docstring)."""
    app.add_exception_handler(ServiceError, _service_error)
    for cls in DOMAIN_ERRORS:
        app.add_exception_handler(cls, _domain_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(Exception, _unexpected)
