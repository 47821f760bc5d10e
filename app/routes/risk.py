"""POST /risk: score a posted concrete scenario (e.g. a recorded test drive)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Query
from pydantic import WithJsonSchema

from app.deps import SettingsDep
from app.schemas import RiskReport
from app.services import risk

router = APIRouter(prefix="/risk", tags=["risk"])

#: riskcore's JSON form's name (``riskcore.scenario.SCHEMA``; a test checks they agree)
SCHEMA = "scengen.concrete-scenario/1"
_NUMBERS = {"type": "array", "items": {"type": "number"}}
_TRACK = {
    "type": "object", "additionalProperties": False,
    "required": ["id", "length", "width", "x", "y", "psi", "v"],
    "properties": {
        "id": {"type": "string", "minLength": 1},
        "length": {"type": "number", "exclusiveMinimum": 0, "description": "m"},
        "width": {"type": "number", "exclusiveMinimum": 0, "description": "m"},
        "x": _NUMBERS, "y": _NUMBERS, "psi": _NUMBERS, "v": _NUMBERS,
        "a": {"anyOf": [_NUMBERS, {"type": "null"}]},
        "yaw_rate": {"anyOf": [_NUMBERS, {"type": "null"}]},
    },
}
#: the JSON schema of a concrete scenario (``riskcore.scenario``'s JSON form); what it
#: cannot say, the validation answers with a 422 naming the field: every series as long as
#: ``t``, ``t`` strictly increasing, ids unique, the service's object and step limits
CONCRETE_SCENARIO_SCHEMA = {
    "title": "ConcreteScenario", "type": "object", "additionalProperties": False,
    "required": ["t", "ego"],
    "properties": {
        "schema": {"type": "string", "enum": [SCHEMA]},
        "t": {**_NUMBERS, "minItems": 2, "description": "time, s, strictly increasing"},
        "ego": _TRACK,
        "objects": {"type": "array", "items": _TRACK},
        "params": {"anyOf": [{"type": "object", "additionalProperties": {"type": "number"}},
                             {"type": "null"}]},
        "seed": {"anyOf": [{"type": "integer"}, {"type": "null"}]},
        "provenance": {"anyOf": [{"type": "object"}, {"type": "null"}]},
    },
}


@router.post("", response_model=RiskReport,
             summary="TTR Monte-Carlo risk of a concrete scenario (its JSON form, schema "
             "scengen.concrete-scenario/1): summary and per-step series")
def score(
    scenario: Annotated[dict[str, Any], WithJsonSchema(CONCRETE_SCENARIO_SCHEMA), Body(
        description="a concrete scenario in the JSON form of riskcore.scenario (at most "
        "SCENGEN_RISK_OBJECTS_LIMIT objects and SCENGEN_RISK_STEPS_LIMIT time steps)")],
    settings: SettingsDep,
    samples: Annotated[bool, Query(description="include every object's per-sample "
                                   "Monte-Carlo arrays (large: ~0.9 MB for 10 s)")] = False,
) -> RiskReport:
    return risk.score_posted(scenario, settings, samples=samples)
