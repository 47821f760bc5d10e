"""The OpenAPI description says everything a client can get back.

FastAPI documents each route's success response and a 422 in its own shape
(``{"detail": [...]}``). The service answers differently: every error has the one body of
``app.errors`` (``{"error": {"status", "message", "field"}}``), 404 for unknown ids, 413
for oversized bodies, 400 for a body that cannot be parsed, 401/403 from the request
guards, and some routes answer CSV, NDJSON, Parquet, zip, HTML or JavaScript.
``install_openapi_extras(app)`` post-processes the generated description once:

* the ``Error`` schema, used by every documented error response (422 included);
* 404 everywhere (an unknown id may be in the path or the body), 400 and 413 on
  operations with a body, 401 and 403 on mutating operations, 409 on a catalogue's
  and on an evaluation's export;
* the media types of the non-JSON responses (``MEDIA_TYPES``).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

ERROR_SCHEMA: dict[str, Any] = {
    "title": "Error",
    "type": "object",
    "required": ["error"],
    "properties": {"error": {
        "type": "object",
        "required": ["status", "message", "field"],
        "properties": {
            "status": {"type": "integer", "description": "the HTTP status"},
            "message": {"type": "string", "description": "what is wrong, for a person"},
            "field": {"anyOf": [{"type": "string"}, {"type": "null"}],
                      "description": "dotted path of the field to blame (body.n, "
                                     "query.offset, path.catalogue_id), if one is"},
        },
    }},
}

ERRORS = {
    "400": "the body cannot be parsed (malformed JSON or form), or the Host header names a "
           "host the service does not answer to (SCENGEN_TRUSTED_HOSTS)",
    "401": "the API key is missing or wrong (only when SCENGEN_API_KEY is set)",
    "403": "a cross-site browser request that would change something",
    "404": "an unknown id (in the path or the body) or page",
    "409": "the catalogue or evaluation is not in a state that allows it (e.g. export "
           "before it is done)",
    "413": "the body is larger than its limit (SCENGEN_BODY_LIMIT_BYTES, "
           "SCENGEN_UPLOAD_LIMIT_BYTES, SCENGEN_UPLOAD_EXPANDED_LIMIT_BYTES)",
    "429": "the client is over a quota (SCENGEN_CLIENT_JOBS_LIMIT, "
           "SCENGEN_CLIENT_QUEUED_SCENARIOS_LIMIT); Retry-After says when to try again",
    "422": "a value out of range or not understood; the message names the field and, for "
           "a limit, its setting",
}

#: the operations that queue a job, so count against the client's quotas (``app.quotas``)
QUOTA_OPERATIONS = {("/catalogues", "post"), ("/evaluations", "post")}

_BINARY = {"type": "string", "format": "binary"}
_TEXT = {"type": "string"}

#: (path, method) -> extra media types of its 200 response
MEDIA_TYPES: dict[tuple[str, str], dict[str, dict[str, Any]]] = {
    ("/catalogues/{catalogue_id}/export", "get"): {
        "application/x-ndjson": {"schema": _TEXT},
        "text/csv": {"schema": _TEXT},
        "application/vnd.apache.parquet": {"schema": _BINARY},
        "application/zip": {"schema": _BINARY},
    },
    ("/evaluations/{evaluation_id}/export", "get"): {
        "application/json": {"schema": {"type": "object"}},  # format=json (default)
        "application/zip": {"schema": _BINARY}},              # xosc, commonroad
    ("/datasets/{dataset_id}/parameters", "get"): {
        "application/json": {"schema": {"type": "object"}},  # format=json (default)
        "text/csv": {"schema": _TEXT}},                       # format=csv
    ("/dashboard/static/plotly.min.js", "get"): {"text/javascript": {"schema": _TEXT}},
    ("/dashboard/static/{name}", "get"): {"text/javascript": {"schema": _TEXT},
                                          "text/css": {"schema": _TEXT}},
}

_METHODS = ("get", "put", "post", "delete", "patch")


def _error_response(text: str) -> dict[str, Any]:
    return {"description": text,
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}


#: how a non-finite float is written (the service's JSON convention, app/schemas.py)
NON_FINITE = {"type": "string", "enum": ["Infinity", "-Infinity", "NaN"]}


def _refs(node: Any) -> set[str]:
    if isinstance(node, dict):
        out = {node["$ref"].rsplit("/", 1)[-1]} if isinstance(node.get("$ref"), str) else set()
        for value in node.values():
            out |= _refs(value)
        return out
    if isinstance(node, list):
        return set().union(*(_refs(v) for v in node)) if node else set()
    return set()


def _allow_non_finite(node: Any) -> Any:
    """Every ``"type": "number"`` in ``node`` also admits "Infinity"/"-Infinity"/"NaN"."""
    if isinstance(node, list):
        return [_allow_non_finite(v) for v in node]
    if not isinstance(node, dict):
        return node
    out = {k: _allow_non_finite(v) for k, v in node.items()}
    if out.get("type") == "number":
        number = {k: out.pop(k) for k in list(out)
                  if k in ("type", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")}
        out["anyOf"] = [number, dict(NON_FINITE)]
    return out


def _response_only_schemas(spec: dict[str, Any]) -> set[str]:
    """Component schemas no request body or parameter refers to (directly or not)."""
    schemas = spec.get("components", {}).get("schemas", {})
    inputs: set[str] = set()
    for item in spec.get("paths", {}).values():
        for method in _METHODS:
            op = item.get(method) or {}
            inputs |= _refs(op.get("requestBody")) | _refs(op.get("parameters"))
    todo = list(inputs)
    while todo:
        name = todo.pop()
        for ref in _refs(schemas.get(name)) - inputs:
            inputs.add(ref)
            todo.append(ref)
    return set(schemas) - inputs


def enrich(spec: dict[str, Any]) -> dict[str, Any]:
    """Add the error responses and media types described in the module docstring; numbers
    in responses also admit the strings of non-finite floats."""
    schemas = spec.setdefault("components", {}).setdefault("schemas", {})
    for name in _response_only_schemas(spec):
        schemas[name] = _allow_non_finite(schemas[name])
    for item in spec.get("paths", {}).values():
        for method in _METHODS:
            for response in (item.get(method) or {}).get("responses", {}).values():
                for media in (response.get("content") or {}).values():
                    if "schema" in media and "$ref" not in media["schema"]:
                        media["schema"] = _allow_non_finite(media["schema"])
    schemas["Error"] = ERROR_SCHEMA
    for path, item in spec.get("paths", {}).items():
        for method in _METHODS:
            op = item.get(method)
            if op is None:
                continue
            responses = op.setdefault("responses", {})
            codes = ["400", "404", "422"]  # 400: also an untrusted Host, on every route
            if "requestBody" in op:
                codes += ["413"]
            if (path, method) in QUOTA_OPERATIONS:
                codes.append("429")
            if method != "get":
                codes += ["401", "403"]
            if "{catalogue_id}" in path or path == "/evaluations/{evaluation_id}/export":
                codes.append("409")
            ok_types = set(responses.get("200", {}).get("content") or {})
            page = ok_types == {"text/html"}  # an HTML page answers its errors as pages
            for code in codes:
                responses[code] = _error_response(ERRORS[code])
                if page:  # a page answers its own errors as pages, validation as JSON
                    responses[code]["content"]["text/html"] = {"schema": _TEXT}
            extra = MEDIA_TYPES.get((path, method))
            if extra:
                ok = responses.setdefault("200", {"description": "OK"})
                content = ok.setdefault("content", {})
                if content.get("application/json", {}).get("schema") == {}:
                    content.pop("application/json")  # FileResponse routes: not JSON
                content.update(extra)
    spec.get("components", {}).get("schemas", {}).pop("HTTPValidationError", None)
    spec.get("components", {}).get("schemas", {}).pop("ValidationError", None)
    return spec


def install_openapi_extras(app: FastAPI) -> None:
    """Make ``app.openapi()`` return the enriched description (built once)."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = enrich(get_openapi(
                title=app.title, version=app.version, openapi_version=app.openapi_version,
                summary=app.summary, description=app.description, routes=app.routes,
                tags=app.openapi_tags, servers=app.servers))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
