"""Scoring a concrete scenario with riskcore (``POST /risk``, ``scengen risk``).

``score(data)`` takes a scenario in its JSON form (a posted body, or a file's content),
validates it and returns its risk report (``app.domain.risk.risk_report``: summary,
per-step series, per-object series, the criticality record). A malformed scenario or bad
settings are ``InvalidInput`` naming the field; ``read_scenario_file`` gives a file's
JSON, a file that is not JSON a ``ScenarioError`` naming the file.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from app import domain
from app.errors import InvalidInput
from app.limits import check_posted_scenario
from app.schemas import RiskReport
from app.settings import Settings
from riskcore import InputSurfaces, RiskSettings, ScenarioError

__all__ = ["read_scenario_file", "risk_settings", "score", "score_posted"]


def risk_settings(overrides: Mapping[str, Any]) -> RiskSettings:
    """Table II's settings with some fields replaced (``RiskSettings.replace``)."""
    return RiskSettings().replace(**dict(overrides))


def read_scenario_file(path: str | Path) -> Any:
    """A scenario file's JSON. NaN / Infinity literals are parsed as floats here, so that
    the scenario's validation rejects them with the name of the field they are in."""
    text = Path(path).read_text(encoding="utf-8")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{path}: not valid JSON ({exc})") from None


#: which ego the summary describes (issue 25: a summary of risk 1 and min THW 0.05 s beside
#: a "preventable" class read as a contradiction; it is the drive of an ego that never
#: reacts, the class is what a careful driver does)
SUMMARY_EGO = ("scripted: the ego drives its track as given and never reacts to the other "
               "vehicles; risk, min_ttr, min_ttc, min_thw are of that drive. How reacting "
               "drivers fare (the careful R157 driver, RSS) is in 'criticality' "
               "(docs/criticality.md)")


def score(data: Any, *, samples: bool = False, settings: RiskSettings | None = None,
          surfaces: InputSurfaces | None = None) -> RiskReport:
    """The risk report of a concrete scenario given in its JSON form; ``samples`` adds
    each object's per-sample Monte-Carlo arrays. Its summary names the ego it describes
    (``summary["ego"]``: the scripted one)."""
    report = domain.score_posted(data, samples=samples, settings=settings, surfaces=surfaces)
    return report.model_copy(update={"summary": {"ego": SUMMARY_EGO, **report.summary}})


#: a track's time series (``riskcore.scenario``); ``a`` and ``yaw_rate`` may be null
SERIES_KEYS = ("x", "y", "psi", "v", "a", "yaw_rate")


def check_json_numbers(data: Any) -> None:
    """Every value of a posted scenario's series is a JSON number (not a string such as
    "1.5" nor a boolean, which numpy would read as numbers): the API's schema of the body
    says so, and the validation is as strict (``InvalidInput`` naming the value)."""
    if not isinstance(data, Mapping):
        return  # riskcore's validation names that
    series: list[tuple[str, Any]] = [("t", data.get("t"))]
    tracks = [("ego", data.get("ego"))]
    objects = data.get("objects")
    if isinstance(objects, list):
        tracks += [(f"objects[{i}]", o) for i, o in enumerate(objects)]
    for where, track in tracks:
        if isinstance(track, Mapping):
            series += [(f"{where}.{k}", track.get(k)) for k in SERIES_KEYS]
    for where, values in series:
        if not isinstance(values, list):
            continue
        for i, v in enumerate(values):
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise InvalidInput(f"{where}[{i}]: expected a number, got "
                                   f"{type(v).__name__}", field=f"body.{where}[{i}]")


def score_posted(data: Any, service: Settings, *, samples: bool = False) -> RiskReport:
    """``POST /risk``: :func:`score` after the service's size limits (objects, steps)."""
    check_posted_scenario(data, service)
    check_json_numbers(data)
    return score(data, samples=samples)
