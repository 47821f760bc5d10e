"""Every error class maps to its status and the one body shape."""

from __future__ import annotations

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from pydantic import BaseModel

from app.errors import (
    Conflict,
    InvalidInput,
    NotFound,
    PayloadTooLarge,
    ServiceUnavailable,
    install_error_handlers,
)
from app.exports import ExportError
from datasets import CutInParamError
from datasets.errors import FormatError
from riskcore.errors import SceneError
from sampler import ConstraintError, EmptyRegionError, NotFittedError
from sampler.region.constraints import Region, parse_constraint


class Body(BaseModel):
    n: int


def _app() -> FastAPI:
    app = FastAPI()
    install_error_handlers(app)
    errors: dict[str, Exception] = {
        "notfound": NotFound("thing 'x' not found", field="path.id"),
        "invalid": InvalidInput("n is too big", field="body.n"),
        "large": PayloadTooLarge("too big"),
        "conflict": Conflict("not finished"),
        "unavailable": ServiceUnavailable("no default model: not loaded"),
        # domain errors: the status by class, the field from the attribute, not the text
        "constraint": ConstraintError("text that names nothing", field="constraints.2",
                                      problem="unknown quantity", value="foo"),
        "empty": EmptyRegionError("nothing inside", n_draws=10),
        "notfitted": NotFittedError("fit first: body.zzz"),
        "scene": SceneError("bad", field="ego.v[3]"),
        "format": FormatError("bad file"),
        "cutin": CutInParamError("p_t: must be > 0 s, got -1"),
        "export": ExportError("row 3: expected a number"),
        # a library's ValueError (numpy, scipy, scikit-learn) is our bug, not the user's
        "library": ValueError("array must not contain infs or NaNs"),
    }

    @app.get("/raise/{kind}")
    def raise_(kind: str) -> None:
        if kind == "crash":
            raise ZeroDivisionError("bug")
        raise errors[kind]

    @app.post("/body")
    def body(b: Body) -> dict[str, int]:
        return {"n": b.n}

    return app


@pytest.mark.parametrize(("kind", "status", "field"), [
    ("notfound", 404, "path.id"),
    ("invalid", 422, "body.n"),
    ("large", 413, None),
    ("conflict", 409, None),
    ("unavailable", 503, None),
    ("constraint", 422, "body.constraints.2"),
    ("empty", 422, "body.constraints"),
    ("notfitted", 409, None),
    ("scene", 422, "body.ego.v[3]"),
    ("format", 422, None),
    ("cutin", 422, None),
    ("export", 422, None),
])
def test_service_errors_have_the_common_shape(kind: str, status: int, field: str | None) -> None:
    with TestClient(_app()) as client:
        r = client.get(f"/raise/{kind}")
    assert r.status_code == status
    body = r.json()
    assert set(body) == {"error"}
    assert body["error"]["status"] == status
    assert body["error"]["field"] == field
    assert isinstance(body["error"]["message"], str) and body["error"]["message"]


def test_validation_errors_name_the_field() -> None:
    with TestClient(_app()) as client:
        r = client.post("/body", json={"n": "many"})
        missing = client.post("/body", json={})
        not_json = client.post("/body", content=b"{", headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "body.n"
    assert "body.n" in r.json()["error"]["message"]
    assert missing.status_code == 422 and missing.json()["error"]["field"] == "body.n"
    # malformed syntax is a 400 naming the body (issue 27 item 5; docs/api.md, and the
    # OpenAPI's 400 "the body cannot be parsed"), a value the schema refuses a 422
    assert not_json.status_code == 400 and not_json.json()["error"]["field"] == "body"


def test_unknown_route_and_unexpected_errors_keep_the_shape() -> None:
    with TestClient(_app(), raise_server_exceptions=False) as client:
        r404 = client.get("/nowhere")
        r500 = client.get("/raise/crash")
        r405 = client.delete("/body")
        library = client.get("/raise/library")
    assert r404.status_code == 404 and r404.json()["error"]["status"] == 404
    assert r405.status_code == 405 and r405.json()["error"]["status"] == 405
    assert r500.status_code == 500
    assert r500.json()["error"]["message"] == "internal error: ZeroDivisionError"
    # a bare ValueError is not a FieldError: not the user's fault, so not a 4xx
    assert library.status_code == 500
    assert library.json()["error"]["message"] == "internal error: ValueError"


def test_one_error_tree_under_a_neutral_base() -> None:
    """Every package's user-input error is a FieldError (riskcore/errors.py draws the tree);
    the app's ServiceError family stays beside it."""
    from app.errors import DOMAIN_ERRORS, ServiceError
    from datasets import DatasetError
    from riskcore import FieldError, RiskcoreError
    from sampler import SamplerError

    for cls in (DatasetError, FormatError, CutInParamError, ExportError, SamplerError,
                ConstraintError, RiskcoreError, SceneError):
        assert issubclass(cls, FieldError), cls
    assert (FieldError,) == DOMAIN_ERRORS
    assert not issubclass(ServiceError, FieldError)
    err = CutInParamError("p_t: must be > 0 s", field="p_t", problem="out of range", value=-1.0)
    assert (err.field, err.problem, err.value) == ("p_t", "out of range", -1.0)


@pytest.mark.parametrize(("text", "field", "problem", "value"), [
    ("foo<3", "name", "unknown quantity", "foo"),
    ("ttc~3", None, "malformed", "ttc~3"),
    ("ttc!=3", "op", "unknown operator", "!="),
    ("ttc<abc", "value", "not a number", "abc"),
    ("ttc<inf", "value", "not finite", "inf"),
])
def test_constraint_errors_carry_structured_fields(text: str, field: str | None,
                                                   problem: str, value: str) -> None:
    with pytest.raises(ConstraintError) as info:
        parse_constraint(text)
    assert (info.value.field, info.value.problem, info.value.value) == (field, problem, value)
    assert info.value.constraint == text


def test_region_errors_carry_structured_fields() -> None:
    with pytest.raises(ConstraintError) as info:
        Region.from_constraints(["ttc<3"], lane_width=12.0)
    assert (info.value.field, info.value.problem, info.value.value) == (
        "lane_width", "out of range", 12.0)
    with pytest.raises(ConstraintError) as info:
        Region.from_constraints([{"name": "ttc", "op": "<", "value": "x"}])
    assert info.value.field == "value" and info.value.value == "x"
