"""Interactive API docs that work without internet, and a landing page at ``/``.

FastAPI's default ``/docs`` (Swagger UI) and ``/redoc`` load their JavaScript and CSS from a
CDN, so they are blank on a machine without internet. FastAPI documents the remedy
(self-hosting the assets: ``docs_url=None, redoc_url=None`` and routes that return
``get_swagger_ui_html`` / ``get_redoc_html`` with local URLs); the assets come from the
``fastapi-offline`` package, which ships exactly these files. Only that package's static
files are used; the routes are ours.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, Response

from app.errors import NotFound

STATIC_PREFIX = "/docs-static"
#: the only files served under STATIC_PREFIX, with their media types
ASSETS = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
    "redoc.standalone.js": "text/javascript; charset=utf-8",
    "favicon.png": "image/png",
}

#: ReDoc's bundle shows a "powered by" logo fetched from this address: the page asked the
#: network for it (issue 25). The served bundle points at a local, plain stand-in.
REDOC_CDN_LOGO = b"https://cdn.redoc.ly/redoc/logo-mini.svg"
LOGO_NAME = "redoc-logo.svg"
LOGO_SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16" '
            b'viewBox="0 0 16 16"><rect width="16" height="16" rx="3" fill="#8a94a3"/></svg>')


@lru_cache(maxsize=1)
def _redoc_js() -> bytes:
    """The ReDoc bundle with its CDN logo address replaced by the local stand-in's."""
    raw = (assets_dir() / "redoc.standalone.js").read_bytes()
    return raw.replace(REDOC_CDN_LOGO, f"{STATIC_PREFIX}/{LOGO_NAME}".encode())


_LANDING = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<link rel="icon" href="{static}/favicon.png">
<style>body{{font:16px/1.5 system-ui,sans-serif;max-width:40em;margin:3em auto;padding:0 1em}}
a{{color:#0645ad}} code{{background:#f3f3f3;padding:0 .2em}}</style></head>
<body><h1>{title} {version}</h1>
<p>Risk-constrained cut-in scenarios over HTTP.</p>
<ul>
<li><a href="/docs">/docs</a> &mdash; interactive API documentation (Swagger UI)</li>
<li><a href="/redoc">/redoc</a> &mdash; the same as a reference page (ReDoc)</li>
<li><a href="/dashboard">/dashboard</a> &mdash; what the model learnt, catalogues, scenarios</li>
<li><a href="/openapi.json">/openapi.json</a> &mdash; the OpenAPI description</li>
<li><a href="/health">/health</a> &mdash; is the service up</li>
</ul>
<p>First request to try: <code>POST /scenarios</code> with
<code>{{"n": 10, "seed": 1, "constraints": ["ttc&lt;3"]}}</code>.</p>
</body></html>
"""


@lru_cache(maxsize=1)
def assets_dir() -> Path:
    """The folder of Swagger UI / ReDoc files inside the installed fastapi-offline."""
    import fastapi_offline

    return Path(fastapi_offline.__file__).resolve().parent / "static"


def install_offline_docs(app: FastAPI) -> None:
    """Add ``/docs``, ``/redoc``, their assets and ``/`` to ``app``, which must have been
    made with ``docs_url=None, redoc_url=None``."""
    openapi_url = app.openapi_url or "/openapi.json"
    title = app.title

    @app.get("/", include_in_schema=False)
    def landing() -> HTMLResponse:
        return HTMLResponse(_LANDING.format(title=title, version=app.version,
                                            static=STATIC_PREFIX))

    @app.get("/docs", include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url, title=f"{title} - API docs",
            swagger_js_url=f"{STATIC_PREFIX}/swagger-ui-bundle.js",
            swagger_css_url=f"{STATIC_PREFIX}/swagger-ui.css",
            swagger_favicon_url=f"{STATIC_PREFIX}/favicon.png")

    @app.get("/redoc", include_in_schema=False)
    def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url=openapi_url, title=f"{title} - API reference",
            redoc_js_url=f"{STATIC_PREFIX}/redoc.standalone.js",
            redoc_favicon_url=f"{STATIC_PREFIX}/favicon.png", with_google_fonts=False)

    @app.get(STATIC_PREFIX + "/{name}", include_in_schema=False)
    def asset(name: str) -> Response:
        if name == "redoc.standalone.js":
            return Response(_redoc_js(), media_type=ASSETS[name],
                            headers={"Cache-Control": "public, max-age=86400"})
        if name == LOGO_NAME:
            return Response(LOGO_SVG, media_type="image/svg+xml",
                            headers={"Cache-Control": "public, max-age=86400"})
        media_type = ASSETS.get(name)
        if media_type is None:
            raise NotFound(f"no documentation asset {name[:64]!r}", field="path.name")
        return FileResponse(assets_dir() / name, media_type=media_type,
                            headers={"Cache-Control": "public, max-age=86400"})
