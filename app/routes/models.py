"""Fitted cut-in models (GMMs): fit on a dataset, list, show."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict, Field

from app import domain, jsonconv
from app.dashboard import rates_views
from app.db.models import ModelRow
from app.deps import ConstraintsQuery, ContextDep, SeedQuery
from app.rates import ModelComparison
from app.schemas import ApiModel
from app.services import models as models_service
from app.services.rates import COMPARE_N_LIMIT

router = APIRouter(prefix="/models", tags=["models"])


class FitRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)  # no silent coercion

    dataset: str = Field(default="tno-cutin", description="id of the dataset to fit on")
    options: dict[str, Any] = Field(
        default_factory=dict,
        description="keyword options of sampler.model.gmm.CutInGMM (e.g. max_components)",
    )


class ModelInfo(ApiModel):
    id: str
    dataset: str = Field(description="id of the dataset it was fitted on")
    default: bool
    n_components: int
    model_hash: str = Field(description="sha256 of the model's JSON")
    options: dict[str, Any]
    created_at: str


class ModelDetail(ModelInfo):
    bic_curve: list[dict[str, Any]] = Field(
        description="per K: k, bic, log_likelihood, n_parameters, converged, error")
    fit_report: dict[str, Any]
    components: list[dict[str, Any]] = Field(
        description="weight, mean_z, covariance_z of each component (z-space)")


class ModelList(ApiModel):
    models: list[ModelInfo]


def _info(row: ModelRow) -> ModelInfo:
    return ModelInfo(id=row.id, dataset=row.dataset_id, default=row.is_default,
                     n_components=row.n_components, model_hash=row.model_hash,
                     options=jsonconv.encode(row.options),
                     created_at=row.created_at.isoformat())


def model_view(row: ModelRow, components: list[dict[str, Any]]) -> ModelDetail:
    # the free-form parts pass through jsonconv.encode (non-finite floats inside Any)
    return ModelDetail(**dict(_info(row)), bic_curve=jsonconv.encode(row.bic_curve),
                       fit_report=jsonconv.encode(row.fit_report),
                       components=jsonconv.encode(components))


@router.get("", response_model=ModelList,
            summary="List fitted models (the default model first)")
def list_models(ctx: ContextDep) -> ModelList:
    return ModelList(models=[_info(r) for r in models_service.list_models(ctx)])


@router.get("/compare", response_model=ModelComparison,
            summary="Two fitted models side by side: marginals with and without a "
            "constraint, P(A) with both intervals and the rates of the same region")
def compare(
    ctx: ContextDep,
    a: Annotated[str, Query(max_length=64, description="a model id ('default' too)")],
    b: Annotated[str, Query(max_length=64, description="another model id")],
    constraints: ConstraintsQuery = "ttc<3",
    n: Annotated[int, Query(ge=1, le=COMPARE_N_LIMIT,
                            description="samples of each model in the region")] = 400,
    seed: SeedQuery = 0,
) -> ModelComparison:
    return rates_views.compare_models(ctx, a, b, constraints, n, seed)


@router.get("/{model_id}", response_model=ModelDetail,
            summary="A model: components, BIC curve, fit report")
def show_model(model_id: str, ctx: ContextDep) -> ModelDetail:
    _, model, row = models_service.model_and_row(ctx, model_id)
    return model_view(row, domain.model_components(model))


@router.post("", status_code=201, response_model=ModelDetail, summary="Fit a GMM on a dataset")
def fit(body: FitRequest, ctx: ContextDep) -> ModelDetail:
    row, model = models_service.fit_on_dataset(ctx, body.dataset, body.options)
    return model_view(row, domain.model_components(model))
