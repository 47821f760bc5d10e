"""One parameter vector -> one scored scenario record: the single join of sampler and riskcore.

:func:`score_vector` builds the concrete scenario of a cut-in parameter vector
(``sampler.scenario.builder.build_scenario``) and scores it with its criticality record
(``riskcore.criticality.evaluate_criticality``: the perception moment, the reference
drivers, ``btn``, the class, Wagner's risk at t_p and its peak); it is
what ``POST /scenarios``, every catalogue chunk, ``scengen sample --score`` and
:func:`sampler.scenario.scoring.score_samples` call, so the same vector with the same lane
width gives the same :class:`ScenarioRecord` whichever way it is asked for.

Error policy (the same everywhere): a vector the builder refuses, or a scenario riskcore
refuses, does not raise. Its record carries ``error`` (``"build: ..."`` or
``"score: ..."``, one line) and no scores, so one bad vector never fails a catalogue.

Seeds: the builder is deterministic, so there is no per-scenario seed. A scenario is
reproduced from its record: ``build_scenario(record.params, lane_width=...)`` with the lane
width of the sample set (the model's). The ``seed`` a scenario carries (``scenario.seed``)
is the seed of the sampler run that drew its vector (the request's or catalogue's seed);
with the same request it reproduces the vector.

JSON: non-finite floats (TTC of an opening gap, a TTR without collision) are +inf in the
record and ``"Infinity"`` in its JSON (pydantic ``ser_json_inf_nan="strings"``, the project's
convention; validation accepts the strings back).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field

from datasets import PARAM_NAMES, ttc_from_gap_dv
from riskcore import ConcreteScenario, InputSurfaces, RiskSettings
from riskcore.criticality import CRITICALITY_FIELDS, CriticalitySettings, evaluate_criticality
from sampler.scenario.builder import build_scenario

__all__ = ["SCORE_FIELDS", "SUPPORT_FIELDS", "OutsideParameter", "ScenarioRecord",
           "score_rows", "score_vector"]

#: the record's score fields: the criticality record's flat names, in order (all None when
#: unscored or on error)
SCORE_FIELDS: tuple[str, ...] = tuple(CRITICALITY_FIELDS)


def _doc(name: str) -> str:
    spec = CRITICALITY_FIELDS[name]
    unit = f" [{spec.unit}]" if spec.unit not in ("", "-") else ""
    return spec.doc + unit


def _criticality(name: str) -> Any:
    return Field(default=None, description=_doc(name))


class OutsideParameter(BaseModel):
    """A parameter of the vector outside the range of the data the model was fitted on."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(description="the parameter")
    excess: float = Field(description="beyond the data's range, in the parameter's unit: "
                          "+ above the largest value seen, - below the smallest")
    excess_sd: float = Field(description="|excess| in standard deviations of the data")
    unit: str = Field(description="the parameter's unit")


#: the record's data-support fields (``sampler.model.support``; docs/sampler.md)
SUPPORT_FIELDS: tuple[str, ...] = ("support", "support_distance", "support_excess",
                                   "support_nearest", "density_pct", "support_outside")


class ScenarioRecord(BaseModel):
    """A sampled cut-in with its scores: one row of a catalogue, one item of
    ``POST /scenarios``, one line of ``scengen sample --score``."""

    model_config = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="strings",
                              populate_by_name=True, serialize_by_alias=True)

    index: int = Field(description="position in the request or catalogue (0 .. n-1)")
    params: dict[str, float] = Field(description="the cut-in parameter vector (SI units)")
    ttc: float = Field(description="time to collision gap / dv in s at the moment the "
                       "cutter's centre crosses the lane marking (+inf: not closing)")
    exposure_weight: float | None = Field(
        default=None, description="the scenario's share of P(A) (weight for rates on the road)")
    # what the data support (sampler.model.support; null: the model has no training rows)
    support: str | None = Field(
        default=None, description="data support: inside (among the real cut-ins the model "
        "was fitted on), near, or extrapolated (the model invents it); docs/sampler.md")
    support_distance: float | None = Field(
        default=None, description="distance to the nearest real cut-in in the model's "
        "standardised transformed space (1 = one standard deviation of the data)")
    support_excess: float | None = Field(
        default=None, description="largest excess of a parameter beyond the data's range, "
        "in the data's standard deviations (0: every parameter inside the range)")
    support_nearest: int | None = Field(
        default=None, description="row of the nearest real cut-in in the model's training "
        "table")
    density_pct: float | None = Field(
        default=None, description="share of the model's physical cut-ins less probable than "
        "this one (the model's own view of how unusual it is)")
    support_outside: list[OutsideParameter] | None = Field(
        default=None, description="the parameters outside the data's range, largest excess "
        "first")
    # the criticality record (riskcore.criticality.CRITICALITY_FIELDS; null: not scored)
    t_p: float | None = _criticality("t_p")
    t_cross: float | None = _criticality("t_cross")
    ttr_true: float | None = _criticality("ttr_true")
    ttr_manoeuvre: str | None = _criticality("ttr_manoeuvre")
    a_req: float | None = _criticality("a_req")
    btn: float | None = _criticality("btn")
    class_: str | None = Field(default=None, alias="class", description=_doc("class"))
    none_collision: bool | None = _criticality("none_collision")
    none_impact_speed: float | None = _criticality("none_impact_speed")
    none_min_gap: float | None = _criticality("none_min_gap")
    r157_cc_collision: bool | None = _criticality("r157_cc_collision")
    r157_cc_impact_speed: float | None = _criticality("r157_cc_impact_speed")
    r157_cc_min_gap: float | None = _criticality("r157_cc_min_gap")
    r157_cc_t_brake: float | None = _criticality("r157_cc_t_brake")
    rss_collision: bool | None = _criticality("rss_collision")
    rss_impact_speed: float | None = _criticality("rss_impact_speed")
    rss_min_gap: float | None = _criticality("rss_min_gap")
    rss_t_brake: float | None = _criticality("rss_t_brake")
    r_dep_tp: float | None = _criticality("r_dep_tp")
    r_ind_tp: float | None = _criticality("r_ind_tp")
    r_dep_cross: float | None = _criticality("r_dep_cross")
    r_ind_cross: float | None = _criticality("r_ind_cross")
    r_dep_tp_r157: float | None = _criticality("r_dep_tp_r157")
    r_ind_tp_r157: float | None = _criticality("r_ind_tp_r157")
    r_dep_cross_r157: float | None = _criticality("r_dep_cross_r157")
    r_ind_cross_r157: float | None = _criticality("r_ind_cross_r157")
    alarm_time: float | None = _criticality("alarm_time")
    risk_peak: float | None = _criticality("risk_peak")
    error: str | None = Field(default=None, description="why the vector has no scores "
                              "('build: ...' or 'score: ...'); null when it was scored")
    scenario: dict[str, Any] | None = Field(
        default=None, description="the concrete scenario (scengen.concrete-scenario/1) when "
        "asked for")

    def scores(self) -> dict[str, float | bool | str | None]:
        """The score fields (``SCORE_FIELDS``, the criticality record) as a flat dict."""
        return {name: getattr(self, "class_" if name == "class" else name)
                for name in SCORE_FIELDS}


def score_vector(
    params: Mapping[str, float],
    *,
    index: int = 0,
    lane_width: float | None = None,
    seed: int | None = None,
    provenance: Mapping[str, Any] | None = None,
    exposure_weight: float | None = None,
    support: Mapping[str, Any] | None = None,
    score: bool = True,
    include_scenario: bool = False,
    builder_kwargs: Mapping[str, Any] | None = None,
    settings: RiskSettings | None = None,
    surfaces: InputSurfaces | None = None,
    criticality: CriticalitySettings | None = None,
    wagner_scan: bool = False,
) -> tuple[ScenarioRecord, ConcreteScenario | None]:
    """Build and score one parameter vector.

    Parameters
    ----------
    params : mapping of str to float
        The vector (``PARAM_NAMES``; extra keys are ignored).
    index : int
        The record's index.
    lane_width : float, optional
        Lane width of the sample set the vector came from (m); None: the builder's default.
    seed : int, optional
        Seed of the sampler run that drew the vector (stored on the scenario only).
    provenance : mapping, optional
        Merged into the scenario's provenance.
    exposure_weight : float, optional
        Copied to the record.
    support : mapping, optional
        The vector's data support (``SUPPORT_FIELDS``, from the model:
        ``CutInGMM.support_measures(...).record(i)``), copied to the record.
    score : bool
        False: build nothing unless ``include_scenario`` (the record has no scores).
    include_scenario : bool
        Put the scenario's JSON form in ``record.scenario``.
    builder_kwargs : mapping, optional
        More ``build_scenario`` arguments (``dt``, ``duration``, ...).
    settings, surfaces : optional
        riskcore's ``RiskSettings`` and ``InputSurfaces`` for Wagner's risk and the TTR
        scan (defaults when None).
    criticality : CriticalitySettings, optional
        The reference drivers' settings (defaults when None).
    wagner_scan : bool
        Also ``alarm_time`` and ``risk_peak`` (Wagner's r_dep of the scripted ego at every
        step until it reaches the level: about two thirds of the record's cost; the peak
        is 1 for 97 % of a ``ttc<3`` catalogue) and the risks at the crossing
        (``r_dep_cross`` ...). Default False: null; the risks at t_p are always there.

    Returns
    -------
    (ScenarioRecord, ConcreteScenario or None)
        The record and the built scenario (None when not built or refused).
    """
    fields = _vector_fields(params, index, exposure_weight, support)
    if not (score or include_scenario):
        return ScenarioRecord(**fields), None
    try:
        scenario = _build(fields["params"], lane_width, seed, provenance, builder_kwargs)
    except ValueError as exc:  # BuilderError, or a bad builder argument
        return ScenarioRecord(**fields, error=f"build: {exc}"), None
    if include_scenario:
        fields["scenario"] = scenario.to_dict()
    if score:
        try:
            crit = evaluate_criticality(scenario, lane_width=lane_width, settings=criticality,
                                        risk_settings=settings, surfaces=surfaces,
                                        wagner_scan=wagner_scan)
        except ValueError as exc:  # riskcore's errors are ValueErrors
            return ScenarioRecord(**fields, error=f"score: {exc}"), scenario
        fields.update(crit.to_record())
    return ScenarioRecord(**fields), scenario


def _vector_fields(params: Mapping[str, float], index: int, exposure_weight: float | None,
                   support: Mapping[str, Any] | None) -> dict[str, Any]:
    """The record's fields that need no scenario: the vector (``PARAM_NAMES`` as floats),
    its index, ttc, exposure weight and data support."""
    vector = {name: float(params[name]) for name in PARAM_NAMES}
    fields: dict[str, Any] = {"index": index, "params": vector,
                              "ttc": float(ttc_from_gap_dv(vector["gap"], vector["dv"])),
                              "exposure_weight": exposure_weight}
    if support is not None:
        fields.update({k: support[k] for k in SUPPORT_FIELDS if k in support})
    return fields


def _build(vector: dict[str, float], lane_width: float | None, seed: int | None,
           provenance: Mapping[str, Any] | None,
           builder_kwargs: Mapping[str, Any] | None) -> ConcreteScenario:
    """``build_scenario`` of the vector with the record's lane width (None: the builder's
    default) and the other builder arguments."""
    kwargs: dict[str, Any] = dict(builder_kwargs or {})
    if lane_width is not None:
        kwargs["lane_width"] = lane_width
    return build_scenario(vector, seed=seed, provenance=provenance, **kwargs)


def score_rows(
    table: pd.DataFrame,
    *,
    start: int = 0,
    exposure_weights: Sequence[float] | np.ndarray | float | None = None,
    provenance: Callable[[int], Mapping[str, Any]] | None = None,
    support: Sequence[Mapping[str, Any] | None] | None = None,
    **kwargs: Any,
) -> Iterator[tuple[ScenarioRecord, ConcreteScenario | None]]:
    """:func:`score_vector` of every row of a parameter table (columns ``PARAM_NAMES``),
    with indices ``start, start + 1, ...``.

    ``exposure_weights`` is one weight per row or one for all; ``provenance(index)`` gives
    each scenario's provenance; ``support`` one data-support dict per row (or None);
    ``kwargs`` go to :func:`score_vector`.
    """
    names = list(PARAM_NAMES)
    values = table[names].to_numpy(dtype=np.float64)
    if exposure_weights is None or isinstance(exposure_weights, float | int):
        weights: list[float | None] = [None if exposure_weights is None
                                       else float(exposure_weights)] * len(values)
    else:
        weights = [float(w) for w in np.asarray(exposure_weights, dtype=np.float64)]
    for k, row in enumerate(values.tolist()):
        index = start + k
        yield score_vector(dict(zip(names, row, strict=True)), index=index,
                           exposure_weight=weights[k],
                           support=None if support is None else support[k],
                           provenance=None if provenance is None else provenance(index),
                           **kwargs)
