"""Request and response schemas shared by several routes, and the service's JSON convention.

JSON convention (one for the whole service): non-finite floats are written as the strings
``"Infinity"``, ``"-Infinity"`` and ``"NaN"`` (pydantic's ``ser_json_inf_nan="strings"``);
request models accept those strings back. Response models derive from :class:`ApiModel`;
JSON built outside pydantic goes through :func:`app.jsonconv.dumps`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    WithJsonSchema,
    field_serializer,
    model_validator,
)
from typing_extensions import TypedDict  # pydantic reads it on Python 3.11 (the tests)

from app import jsonconv
from sampler import SAMPLER_NAMES
from sampler.region import constraint_pattern
from sampler.scenario import ScenarioRecord

__all__ = ["SEED_MAX", "ApiModel", "ConstraintText", "JsonFloat", "PRegion", "PRegionJSON",
           "PRegionReport", "RiskReport", "SamplingRequest",
           "ScenarioRecord", "SutInfo", "schema_enum"]

#: the largest seed a request may give: the largest integer every JSON parser holds exactly
#: (JavaScript's Number.MAX_SAFE_INTEGER), so a seed survives any client unchanged
SEED_MAX = 2**53 - 1

#: the region a request gets when it names none
DEFAULT_CONSTRAINTS: tuple[str, ...] = ("ttc<3",)

#: the ``sampler`` field's values: the sampler's registry (``sampler.SAMPLER_NAMES``), so
#: the API's enum and its 422 list the samplers that exist
if TYPE_CHECKING:
    SamplerName = str
else:
    SamplerName = Literal[SAMPLER_NAMES]


#: a constraint in the short form: its grammar (``sampler.region.constraint_pattern``: the
#: quantity names, the operators, a number in ASCII digits) is in the JSON schema; the
#: value is checked by the parser, whose 422 names the constraint and what is wrong
#: ("unknown quantity 'x'; did you mean ..."), which a pattern mismatch could not say
ConstraintText = Annotated[str, WithJsonSchema({
    "type": "string", "pattern": constraint_pattern(),
    "description": "NAME OP VALUE, e.g. 'ttc<3' (docs/sampler.md lists the names)"})]


def schema_enum(values: tuple[str, ...] | list[str]) -> dict[str, object]:
    """A query parameter's ``json_schema_extra`` listing its values (the route checks them
    and answers a 422 that names the valid ones)."""
    return {"enum": list(values)}


class ApiModel(BaseModel):
    """Base of every response model: the service's JSON convention for inf/NaN.

    FastAPI's response path keeps the convention for typed float fields but not for floats
    inside ``Any`` or union-with-str values: pass those through ``app.jsonconv.encode``."""

    model_config = ConfigDict(ser_json_inf_nan="strings")


class SamplingRequest(BaseModel):
    """The fields every sampling request shares (POST /scenarios, POST /catalogues)."""

    # strict: false is not a seed, 0 is not a boolean, "5" is not a number
    model_config = ConfigDict(extra="forbid", strict=True)

    model: str = Field(default="default", description="model id ('default': the embedded "
                       "data's model)")
    constraints: list[ConstraintText] = Field(default_factory=lambda: list(DEFAULT_CONSTRAINTS),
                                   description="risk-region constraints, e.g. 'ttc<3'")
    seed: int = Field(default=0, ge=0, le=SEED_MAX, description="random seed of the sampler")
    sampler: SamplerName = Field(default="auto", description="rejection, mcmc, or auto "
                                 "(rejection unless the region is rare)")
    wagner_scan: bool = Field(default=False, description="with score: also Wagner's "
                              "scan: alarm_time, risk_peak and the risks at the crossing "
                              "(about two thirds of the scoring cost; null otherwise)")


#: a float in the service's JSON convention: a number, or "Infinity", "-Infinity", "NaN"
JsonFloat = float | str


class _PRegionFields(TypedDict):
    """``sampler.methods.PRegion``'s fields (``to_dict``) and ``ci`` = [ci_low, ci_high]."""

    estimate: JsonFloat
    ci_low: JsonFloat
    ci_high: JsonFloat
    confidence: float
    method: str
    n_draws: int
    n_hits: int
    p_bounds: JsonFloat
    p_bounds_ci: list[JsonFloat]
    p_joint: JsonFloat
    cov: JsonFloat | None
    ci: list[JsonFloat]


class PRegionReport(TypedDict, total=False):
    """What the uncertainty report adds to a P(A) (``sampler.rates.uncertainty_report``):
    its two intervals, the model interval's details (``app.rates.ModelInterval``) or why
    there is none, and the rates (``app.rates.RegionRates``)."""

    mc_ci: list[JsonFloat]
    model_ci: list[JsonFloat] | None
    model_interval_error: str
    model_interval: dict[str, Any]
    rates: dict[str, Any]


class PRegionJSON(_PRegionFields, PRegionReport, total=False):
    """P(A) as the service keeps it from the sampler's result to the store (a catalogue's
    ``p_region`` column, ``domain.SampleResult.p_region``, a chunk's diagnostics), in the
    JSON convention and in this key order: ``app.domain.sampling.region_dict`` writes it,
    the report's keys follow. :class:`PRegion` reads it (the report's keys as extras)."""


class PRegion(ApiModel):
    """P(A): the model's probability mass of the constraint region, with its interval.

    The one P(A) schema of the responses (POST /scenarios, a catalogue's status, the
    dashboard's shift view): ``sampler.methods.PRegion``'s fields plus ``ci``; the keys the
    uncertainty report adds (``mc_ci``, ``model_ci``, ``model_interval``, ``rates``) pass
    through as they are. A float that is not defined is null (the dashboard's plot data);
    so is a field a stand-in estimate (tests, a known P(A)) does not give."""

    model_config = ConfigDict(extra="allow", ser_json_inf_nan="strings")

    estimate: float | None = Field(description="point estimate of P(A)")
    ci: list[float | None] = Field(description="[low, high] confidence interval of P(A)")
    ci_low: float | None = None
    ci_high: float | None = None
    confidence: float | None = Field(default=None, description="level of ci, e.g. 0.95")
    method: str | None = Field(default=None, description="how P(A) was estimated: mc, "
                               "envelope, is, subset, subset-is or split (a sum of parts)")
    n_draws: int | None = Field(default=None, description="draws behind the estimate")
    n_hits: int | None = Field(default=None, description="of those, inside the region")
    p_bounds: float | None = Field(default=None, description="P(B), the model's mass "
                                   "inside the physical bounds")
    p_bounds_ci: list[float | None] | None = None
    p_joint: float | None = Field(default=None, description="P(A and B)")
    cov: float | None = Field(default=None, description="coefficient of variation of the "
                              "estimate, when known")

    @model_validator(mode="before")
    @classmethod
    def _ci_of_its_ends(cls, data: Any) -> Any:
        """``ci`` = [ci_low, ci_high] for a P(A) stored without it (as region_dict adds)."""
        if isinstance(data, dict) and "ci" not in data and "ci_low" in data:
            data = {**data, "ci": [data.get("ci_low"), data.get("ci_high")]}
        return data


class RiskReport(ApiModel):
    """A scenario's Monte-Carlo TTR risk (layout ``scengen.scenario-risk/1``)."""

    format: str
    settings: dict[str, Any] = Field(description="riskcore's RiskSettings used")
    surfaces: dict[str, Any] = Field(description="input surfaces: source, interim")
    summary: dict[str, float | str | None] = Field(
        description="the scored record's fields: risk, risk_ind, min_ttr, ...")
    evasion_bits: dict[str, int]
    series: dict[str, list[float]] = Field(
        description="per step: t, r_dep, r_ind, min_ttr, ttc, wttc, thw")
    objects: list[dict[str, Any]] = Field(
        description="per object: id, per-step series, and with samples=true the "
        "per-sample arrays (a, omega, weight, ttr, collision_time, evasion)")
    criticality: dict[str, float | bool | str | None] | None = Field(
        description="the scenario's criticality record taken as a cut-in (class, btn, "
        "a_req, ttr_true, the reference drivers' outcomes, ...; docs/criticality.md); "
        "null when it is not a cut-in (see criticality_error)")
    criticality_error: str | None = Field(
        description="why there is no criticality record (null when there is one)")

    @field_serializer("objects", when_used="json")
    def _objects_json(self, objects: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """The per-object series in the JSON convention (+inf as "Infinity"): the response
        path keeps it for typed floats only, not for floats inside these free-form dicts."""
        encoded: list[dict[str, Any]] = jsonconv.encode(objects)
        return encoded

    @field_serializer("settings", "surfaces", when_used="json")
    def _free_json(self, value: dict[str, Any]) -> dict[str, Any]:
        """The settings and surfaces in the JSON convention, as the objects."""
        encoded: dict[str, Any] = jsonconv.encode(value)
        return encoded

    @field_serializer("summary", when_used="json")
    def _summary_json(self, value: dict[str, float | str | None]
                      ) -> dict[str, float | str | None]:
        """The summary in the JSON convention (a float in a union with str loses it)."""
        encoded: dict[str, float | str | None] = jsonconv.encode(value)
        return encoded

    @field_serializer("criticality", when_used="json")
    def _criticality_json(self, value: dict[str, float | bool | str | None] | None
                          ) -> dict[str, float | bool | str | None] | None:
        """The criticality record in the JSON convention, as the summary."""
        encoded: dict[str, float | bool | str | None] | None = jsonconv.encode(value)
        return encoded


# a registered system under test (GET /suts, scengen evaluate --list-suts)
class SutInfo(ApiModel):
    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="strings")

    name: str
    origin: str = Field(description="builtin | entry point (<distribution>)")
    summary: str
    parameters: dict[str, Any]
    source: str
