"""riskcore for the service: score a posted scenario, the per-step risk profile on demand.

The reports are built from whole numpy arrays (``tolist`` of stacked arrays, a lookup
table for the evasion labels) and keep +inf as a float: the service's JSON convention
writes it as ``"Infinity"``. Per-sample arrays (the Monte-Carlo draws, ~0.9 MB for a 10 s
scenario) are only built when asked for.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from app import jsonconv
from app.errors import InvalidInput
from app.schemas import RiskReport
from riskcore import (
    MANOEUVRES,
    RESULT_FORMAT,
    ConcreteScenario,
    InputSurfaces,
    RiskcoreError,
    RiskSettings,
    ScenarioRisk,
    evaluate_scenario,
    evasion_label,
)
from riskcore.criticality import evaluate_criticality

__all__ = ["SERIES", "criticality_of", "parse_scenario", "risk_report", "scenario_risk_series",
           "score_posted"]

#: per-step series of a scenario's risk profile
SERIES = ("r_dep", "r_ind", "min_ttr", "ttc", "wttc", "thw")
_OBJECT_SERIES = ("risk", "min_ttr", "ttc", "wttc", "thw", "a0", "omega0", "mean_a", "std_a",
                  "mean_omega", "std_omega", "n_collisions")
_SAMPLES = ("a", "omega", "weight", "ttr", "collision_time")
#: evasion label of every bit mask of the manoeuvres (None where nothing collides)
_LABELS = np.array([evasion_label(m, True) for m in range(1 << len(MANOEUVRES))],
                   dtype=object)


def score_scenario(risk: ScenarioRisk) -> dict[str, float | str | None]:
    """The flat summary of a scenario's Wagner risk (+inf kept): its maxima and minima over
    the run."""
    k = risk.step_of_max_risk
    return {"risk": float(risk.risk), "risk_ind": float(risk.risk_ind),
            "min_ttr": float(risk.min_ttr), "min_ttc": float(risk.min_ttc),
            "min_wttc": float(risk.min_wttc), "min_thw": float(risk.min_thw),
            "min_ttr_evasion": risk.min_ttr_evasion, "t_of_max_risk": float(risk.t[k])}


def _field(exc: RiskcoreError) -> str:
    return "body" if exc.field is None else f"body.{exc.field}"


def parse_scenario(data: Any) -> ConcreteScenario:
    """A posted concrete scenario (JSON form); InvalidInput naming the field if malformed."""
    try:
        return ConcreteScenario.from_dict(data)
    except RiskcoreError as exc:
        raise InvalidInput(str(exc), field=_field(exc)) from None


def _evasion(mask: NDArray[np.int64], collision_time: NDArray[np.float64]) -> list[Any]:
    labels = _LABELS[mask]
    labels[~np.isfinite(collision_time)] = None
    out: list[Any] = labels.tolist()
    return out


def criticality_of(scenario: ConcreteScenario) -> dict[str, Any]:
    """The criticality record of a posted scenario taken as a cut-in (the cutter: object
    ``"cutter"``, else the first): ``{"criticality": record, "criticality_error": None}``,
    or ``{"criticality": None, "criticality_error": why}`` when it is not one (no object,
    no lateral movement towards the ego, a generated scenario cut off early)."""
    try:
        record = evaluate_criticality(scenario).to_record()
    except RiskcoreError as exc:
        return {"criticality": None, "criticality_error": str(exc)}
    return {"criticality": record, "criticality_error": None}


def risk_report(risk: ScenarioRisk, *, samples: bool = False,
                scenario: ConcreteScenario | None = None) -> RiskReport:
    """A scenario's risk as JSON-ready data (``format`` scengen.scenario-risk/1 layout):
    ``summary`` (the scored record's fields), ``series`` per step, ``objects`` with their
    per-step series, and with ``samples`` each object's per-sample arrays. Given the
    ``scenario``, also its criticality record (:func:`criticality_of`; without it both
    criticality fields are null)."""
    series: dict[str, Any] = {"t": np.asarray(risk.t, dtype=np.float64).tolist()}
    for name in SERIES:
        series[name] = risk.series(name).tolist()
    objects = []
    for k, oid in enumerate(risk.object_ids):
        per = [scene.objects[k] for scene in risk.scenes]
        obj: dict[str, Any] = {"id": oid, "series": {
            name: np.array([getattr(o, name) for o in per]).tolist() for name in _OBJECT_SERIES}}
        if samples:
            obj["samples"] = {name: np.stack([getattr(o, name) for o in per]).tolist()
                              for name in _SAMPLES}
            obj["samples"]["evasion"] = _evasion(np.stack([o.evasion for o in per]),
                                                 np.stack([o.collision_time for o in per]))
        objects.append(obj)
    crit = (criticality_of(scenario) if scenario is not None
            else {"criticality": None, "criticality_error": None})
    return RiskReport(
        format=RESULT_FORMAT,
        settings=risk.settings.to_dict(),
        surfaces={"source": risk.surfaces_source, "interim": risk.surfaces_interim},
        summary=score_scenario(risk),
        evasion_bits={m.name: 1 << i for i, m in enumerate(MANOEUVRES)},
        series=series,
        objects=objects,
        criticality=crit["criticality"],
        criticality_error=crit["criticality_error"],
    )


def score_posted(data: Any, *, samples: bool = False, settings: RiskSettings | None = None,
                 surfaces: InputSurfaces | None = None) -> RiskReport:
    """Score a posted concrete scenario (its JSON form): :func:`risk_report`."""
    scenario = parse_scenario(data)
    try:
        risk = evaluate_scenario(scenario, settings, surfaces)
    except RiskcoreError as exc:
        raise InvalidInput(str(exc), field=_field(exc)) from None
    return risk_report(risk, samples=samples, scenario=scenario)


def scenario_risk_series(scenario: ConcreteScenario) -> dict[str, Any]:
    """The dashboard's risk profile of one scenario: ``summary`` and the per-step
    ``series`` (``t``, ``r_dep``, ``r_ind``, ``min_ttr``, ``ttc``, ``wttc``, ``thw``) as plot
    data: non-finite values are null (a gap in the plotted line)."""
    risk = evaluate_scenario(scenario)
    series = {"t": np.asarray(risk.t, dtype=np.float64)}
    for name in SERIES:
        series[name] = risk.series(name)
    return {"summary": jsonconv.plot_values(score_scenario(risk)),
            "series": {name: jsonconv.plot_values(v) for name, v in series.items()}}
