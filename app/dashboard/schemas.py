"""Response models of the dashboard's JSON views (``/dashboard/api/…``, docs/dashboard.md).

All derive from ``app.schemas.ApiModel``: a non-finite float in a typed field is written
as ``"Infinity"``, ``"-Infinity"`` or ``"NaN"`` (the service's one convention). Plot arrays
(``list[float | None]``) carry null where a value is not finite or not defined: plotly draws
null as a gap (``app.jsonconv.plot_values``). Free-form parts are plain JSON values: the
catalogue status in its stored form (``app.statuses.catalogue_status_plain``), the scenario
summary through ``app.jsonconv.encode``. The views build these models directly.
"""

from __future__ import annotations

from typing import Any

from pydantic import ConfigDict, Field

from app.schemas import ApiModel, PRegion
from sampler.scenario import ScenarioRecord

__all__ = [
    "CatalogueCriticalityView",
    "DriverProfile",
    "EvaluationBrief",
    "EvaluationOverview",
    "EvaluationScatter",
    "HistogramView",
    "ModelFitView",
    "PlotValues",
    "RunProfileView",
    "ScenarioView",
    "ShiftView",
]

PlotValues = list[float | None]


class HistogramView(ApiModel):
    """Counts on ``edges`` (bins closed on the left, the last one on both sides)."""

    edges: list[float]
    counts: list[int]
    density: list[float] = Field(description="counts / (n_finite · bin width)")
    n: int = Field(description="values asked for (all rows of the selection)")
    n_finite: int
    below: int = Field(description="finite values below the first edge")
    above: int = Field(description="finite values above the last edge")
    n_nonfinite: int = Field(description="values not finite or missing")
    n_inf: int | None = Field(default=None, description="of those, +inf (SQL histograms)")
    n_null: int | None = Field(default=None, description="of those, null (SQL histograms)")


# --------------------------------------------------------------------------- view 1
class DensityCurve(ApiModel):
    x: PlotValues
    y: PlotValues


class FitParameter(ApiModel):
    name: str
    label: str = Field(description="axis title with the unit")
    histogram: HistogramView
    density: DensityCurve | None = Field(description="the model's marginal density; null "
                                         "when the model does not include the parameter")
    fixed: float | None = Field(default=None, description="the value of a parameter the "
                                "model does not include")


class CornerPoints(ApiModel):
    n_total: int
    n_shown: int
    values: dict[str, PlotValues]


class CornerView(ApiModel):
    names: list[str]
    labels: dict[str, str]
    default: list[str]
    data: CornerPoints
    model: CornerPoints


class ModelFitView(ApiModel):
    """View 1: the dataset's histograms with the model's marginal densities."""

    model: str
    dataset: str
    dataset_name: str
    n_data: int
    n_components: int
    features: list[str]
    parameters: list[FitParameter]
    corner: CornerView
    density_method: str


# --------------------------------------------------------------------------- view 2
class ShiftParameter(ApiModel):
    name: str
    label: str
    unconstrained: HistogramView
    constrained: HistogramView
    mean_unconstrained: float | None
    mean_constrained: float | None


class ShiftView(ApiModel):
    """View 2: constrained against unconstrained samples."""

    source: str = Field(description="'preview' (drawn now) or 'catalogue'")
    catalogue: str | None = None
    model: str
    constraints: list[str]
    n: int
    seed: int
    n_reference: int
    p_region: PRegion | None
    parameters: list[ShiftParameter]


# --------------------------------------------------------------------------- view 3
class Diagnostics(ApiModel):
    chunks: int
    methods: list[str]
    acceptance_mean: float | None
    acceptance_min: float | None
    tau_max: float | None
    ess_total: float | None
    n_draws: float | None
    warnings: list[str]


class ClassCount(ApiModel):
    name: str = Field(description="the class (docs/criticality.md)")
    label: str = Field(description="what it means, for the page")
    count: int


class DriverImpact(ApiModel):
    driver: str
    label: str
    histogram: HistogramView = Field(description="impact speeds [m/s] of the scenarios "
                                     "in which this driver collides (n = their number)")


class RiskAtPerception(ApiModel):
    scripted: HistogramView = Field(description="r_dep at t_p, scripted ego")
    r157: HistogramView = Field(description="r_dep at t_p, ego = R157 careful driver")


class CriticalityScatter(ApiModel):
    index: list[int]
    ttc: list[float]
    btn: list[float]
    cls: list[str] = Field(description="criticality class of each point")
    n_total: int
    n_plottable: int
    n_shown: int
    n_ttc_inf: int
    n_btn_inf: int
    selection: str


class TopScenario(ApiModel):
    index: int
    btn: float | None
    a_req: float | None
    class_: str | None = Field(alias="class", serialization_alias="class")
    ttr_true: float | None
    ttr_manoeuvre: str | None
    ttc: float | None = Field(description="null: +inf (an opening gap)")
    t_p: float | None
    r157_cc_collision: bool | None
    r157_cc_impact_speed: float | None
    support: str | None = Field(default=None, description="inside | near | extrapolated "
                                "(null: stored without it)")

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)


class CatalogueCriticalityView(ApiModel):
    """View 3: a catalogue's criticality (histograms counted in SQL)."""

    catalogue: dict[str, Any] = Field(description="the catalogue's status (GET /catalogues/{id})")
    n_rows: int
    n_scored: int
    diagnostics: Diagnostics
    classes: list[ClassCount]
    n_unscored: int
    decel_max: float = Field(description="the careful driver's deceleration [m/s²]: "
                             "a_req = btn · decel_max")
    btn: HistogramView
    ttr_true: HistogramView
    impact_speed: list[DriverImpact]
    r_dep_tp: RiskAtPerception
    alarm_time: HistogramView
    scatter: CriticalityScatter
    top: list[TopScenario]


# --------------------------------------------------------------------------- view 4
class TrackView(ApiModel):
    id: str | None = None
    length: float | None = None
    width: float | None = None
    x: PlotValues
    y: PlotValues
    psi: PlotValues
    v: PlotValues


class ProfilesView(ApiModel):
    """Wagner's risk over time for the scripted and the R157 driver's ego."""

    t: list[float]
    r_dep: PlotValues
    r_ind: PlotValues
    r_dep_r157: PlotValues
    r_ind_r157: PlotValues
    r157_ego: TrackView
    t_p: float | None
    t_cross: float | None
    r157_t_brake: float | None


class ScenarioView(ApiModel):
    """View 4: one scenario."""

    catalogue: str
    index: int
    params: dict[str, float]
    trajectory_source: str
    lane_width: float | None
    t: list[float]
    ego: TrackView
    objects: list[TrackView]
    record: ScenarioRecord = Field(description="the stored criticality record")
    summary: dict[str, Any] = Field(description="the scripted ego's risk summary (seed 000)")
    series: dict[str, PlotValues]
    profiles: ProfilesView | None = Field(description="null when the record could not be "
                                          "computed for this scenario (profiles_error says why)")
    profiles_error: str | None = None


# --------------------------------------------------------------------------- section 7
class EvaluationBrief(ApiModel):
    """The evaluation's state (``GET /evaluations/{id}``, these fields)."""

    id: str
    status: str
    sut: str
    model: str
    seed: int
    constraints: list[str]
    runs_done: int
    runs_planned: int
    progress: float
    collisions_so_far: int
    error: str | None


class EvaluationScatter(ApiModel):
    """Peak r_dep (or the impact speed, see ``note``) against btn, one point a run."""

    run: list[int]
    btn: PlotValues
    r_dep_peak: PlotValues
    impact_speed: PlotValues
    collided: list[bool]
    vs_careful: list[str | None]
    note: str | None


class DriverProfile(ApiModel):
    """One driver's drive of the run: speed, acceleration and r_dep over time."""

    name: str
    t: PlotValues
    v: PlotValues
    a: PlotValues
    t_risk: PlotValues | None = Field(description="null: r_dep not computed")
    r_dep: PlotValues | None
    collided: bool
    impact_speed: float | None
    min_gap: float | None


class EvaluationOverview(ApiModel):
    """The "system under test" section: the evaluation, its figures and the careful
    driver's, the failures, the r_dep-against-btn scatter (plot data: null = gap)."""

    evaluation: EvaluationBrief
    figures: dict[str, Any] | None
    careful: dict[str, Any] | None = Field(description="the latest finished evaluation of "
                                           "r157_cc on the same model and region (status "
                                           "done, figures), else the latest queued or "
                                           "running one (figures null, runs_done, "
                                           "runs_planned), or null")
    careful_request: dict[str, Any] = Field(description="the POST /evaluations body that "
                                            "evaluates r157_cc on the same model, region, "
                                            "seed, runs and simulator settings")
    failures_total: int = Field(description="the collided runs")
    failures_pilot: int = Field(description="how many of them are pilot runs of a "
                                "cross-entropy campaign (left out of the estimate)")
    failures: list[dict[str, Any]] = Field(description="the first 25 collided runs: those "
                                           "the estimate counts by weight, highest first, "
                                           "then the pilot ones; each run's record with "
                                           "counted and share (its weight over the sum of "
                                           "the counted collided runs' weights; null for a "
                                           "pilot run or until done)")
    scatter: EvaluationScatter


class RunProfileView(ApiModel):
    """One run driven again by the SUT and by the careful driver (plot data)."""

    run: dict[str, Any]
    drivers: dict[str, DriverProfile]
