"""Request guards in front of every route (one ASGI middleware).

* **Host** (every request): the ``Host`` header's name (port left out) must be one of
  ``trusted_hosts`` (default the loopback names, plus ``host`` when the service is bound to
  a name or a specific address); else 400 naming ``header.host``. This is what defeats DNS
  rebinding: a page of evil.example whose name is made to resolve to 127.0.0.1 talks to
  the service same-origin, but its requests carry ``Host: evil.example``.
* **Body size**: a dataset upload may be ``upload_limit_bytes`` (the route counts the
  files as well), any other body ``body_limit_bytes``; above that 413 naming the limit,
  before the body is read. A body without ``Content-Length`` (chunked) is counted as it
  arrives.
* **API key** (optional): when ``api_key`` is set, every mutating request (POST, PUT,
  PATCH, DELETE) and every costly read (``COSTLY_READS``: sampling, estimating or building
  files, seconds of work each) needs it in the ``X-API-Key`` header (or ``Authorization:
  Bearer``); else 401. Reads of what is stored (a status, a page of scenarios) stay open.
* **Cross-site requests**: a browser on another site can POST a form (multipart, urlencoded
  or text/plain) to the service without asking first (no CORS pre-flight). A mutating
  request that a browser marks as cross-site (``Sec-Fetch-Site: cross-site``) or whose
  ``Origin`` is not this service's is refused (403). Clients that are not browsers send
  neither header and are not affected.
"""

from __future__ import annotations

import hmac
import json
import re
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any
from urllib.parse import urlsplit

from app.errors import error_body
from app.settings import Settings

#: bind addresses that mean "every interface": they name no host to trust
_WILDCARD_BINDS = frozenset({"0.0.0.0", "::", "", "*"})

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

MUTATING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
#: reads that cost seconds of work (they sample, estimate, or build files): with an API
#: key set they need it like the writes (issue 27 item 4)
COSTLY_READS = tuple(re.compile(p) for p in (
    r"/models/compare",
    r"/dashboard/api/models/[^/]+/(shift|rates|fit)",
    r"/dashboard/api/catalogues/[^/]+/shift",
    r"/(catalogues|evaluations)/[^/]+/export",
))


def costly_read(method: str, path: str) -> bool:
    """Whether a request is a read that ``COSTLY_READS`` lists."""
    stripped = path.rstrip("/") or "/"
    return method in ("GET", "HEAD") and any(p.fullmatch(stripped) for p in COSTLY_READS)
#: the upload route (multipart, its own larger limit)
UPLOAD_PATH = "/datasets"


class _TooLarge(BaseException):
    """Raised from ``receive`` past the limit; a BaseException so that no route's
    ``except Exception`` turns it into a 400."""


async def _send_error(send: Send, status: int, message: str, field: str | None,
                      headers: list[tuple[bytes, bytes]] | None = None) -> None:
    body = json.dumps(error_body(status, message, field)).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()), *(headers or [])]})
    await send({"type": "http.response.body", "body": body})


def _header(scope: Scope, name: bytes) -> str | None:
    for key, value in scope.get("headers", []):
        if key.lower() == name:
            return bytes(value).decode("latin-1")
    return None


def _same_origin(scope: Scope, origin: str) -> bool:
    host = _header(scope, b"host")
    if origin == "null" or host is None:
        return False
    return urlsplit(origin).netloc.lower() == host.lower()


def host_name(host_header: str) -> str:
    """The name of a ``Host`` header without its port, lower case (``[::1]:8000`` ->
    ``::1``)."""
    value = host_header.strip().lower()
    if value.startswith("["):  # an IPv6 literal
        end = value.find("]")
        return value[1:end] if end > 0 else value
    if value.count(":") == 1:
        value = value.split(":", 1)[0]
    return value.rstrip(".")


def trusted_host_names(settings: Settings) -> list[str]:
    """The host names the service answers to (``trusted_hosts`` and the bind address)."""
    names = [h.strip().lower().strip("[]") for h in settings.trusted_hosts if h.strip()]
    bind = settings.host.strip().lower().strip("[]")
    if bind not in _WILDCARD_BINDS and bind not in names:
        names.append(bind)
    return names


def host_allowed(host_header: str | None, trusted: list[str]) -> bool:
    """Whether a request with this ``Host`` header may be answered."""
    if "*" in trusted:
        return True
    if not host_header:
        return False
    name = host_name(host_header)
    for pattern in trusted:
        if pattern.startswith("*."):
            if name.endswith(pattern[1:]) and len(name) > len(pattern) - 1:
                return True
        elif name == pattern:
            return True
    return False


class RequestGuards:
    """The ASGI middleware; ``settings()`` gives the current settings."""

    def __init__(self, app: ASGIApp, settings: Callable[[], Settings]) -> None:
        self.app = app
        self.settings = settings

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        settings = self.settings()
        host = _header(scope, b"host")
        if not host_allowed(host, trusted_host_names(settings)):
            await _send_error(send, 400, f"host {host_name(host or '')!r} is not one this "
                              "service answers to (SCENGEN_TRUSTED_HOSTS)", "header.host")
            return
        method = scope.get("method", "GET")
        costly = costly_read(method, scope.get("path", ""))
        if method not in MUTATING and not costly:
            await self.app(scope, receive, send)
            return
        # cross-site browser requests
        fetch_site = _header(scope, b"sec-fetch-site")
        origin = _header(scope, b"origin")
        if not costly and (fetch_site == "cross-site" or (origin is not None
                                                          and not _same_origin(scope, origin))):
            await _send_error(send, 403, "cross-site request refused: this service "
                              "accepts changes only from its own pages and from clients "
                              "that are not browsers", "header.origin")
            return
        # API key
        key = settings.api_key.get_secret_value() if settings.api_key is not None else None
        if key:
            given = _header(scope, b"x-api-key")
            auth = _header(scope, b"authorization")
            if given is None and auth is not None and auth.lower().startswith("bearer "):
                given = auth[7:].strip()
            if given is None or not hmac.compare_digest(given.encode(), key.encode()):
                await _send_error(send, 401, "this endpoint needs the service's API key in "
                                  "the X-API-Key header (SCENGEN_API_KEY)", "header.x-api-key",
                                  [(b"www-authenticate", b"ApiKey")])
                return
        if costly:
            await self.app(scope, receive, send)
            return
        # body size
        upload = scope.get("path", "").rstrip("/") == UPLOAD_PATH
        limit = settings.upload_limit_bytes + 64 * 1024 if upload else settings.body_limit_bytes
        setting = "SCENGEN_UPLOAD_LIMIT_BYTES" if upload else "SCENGEN_BODY_LIMIT_BYTES"
        shown = settings.upload_limit_bytes if upload else settings.body_limit_bytes
        message = f"request body larger than the limit of {shown} bytes ({setting})"
        field = "body.files" if upload else "body"
        length = _header(scope, b"content-length")
        if length is not None and length.strip().isdigit():
            if int(length) > limit:
                await _send_error(send, 413, message, field)
                return
            await self.app(scope, receive, send)
            return
        # no length given: count the chunks as they arrive
        seen = 0
        started = False

        async def counted() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise _TooLarge
            return msg

        async def tracking_send(msg: Message) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, counted, tracking_send)
        except _TooLarge:
            if not started:
                await _send_error(send, 413, message, field)
