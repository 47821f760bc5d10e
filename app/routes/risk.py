"""POST /risk: score a posted concrete scenario (e.g. a recorded test drive)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body

from app import domain

router = APIRouter(prefix="/risk", tags=["risk"])


@router.post("", summary="TTR Monte-Carlo risk of a concrete scenario (its JSON form, "
             "schema scengen.concrete-scenario/1): per-step series and summary")
def score(scenario: Annotated[dict[str, Any], Body(
        description="a concrete scenario in the JSON form of riskcore.scenario")]) -> Any:
    return domain.score_posted(scenario)
