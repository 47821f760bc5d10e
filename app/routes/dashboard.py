"""The dashboard: the page (``/dashboard``, ``/dashboard/catalogues/{id}``), its static
files (plotly.js served from the installed plotly package: no network needed) and its JSON
views under ``/dashboard/api/`` (errors in the service's one error shape)."""

from __future__ import annotations

import gzip
import hashlib
import html
import json
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, HTMLResponse, Response

from app.dashboard import evaluation_views, views
from app.dashboard.schemas import (
    CatalogueCriticalityView,
    EvaluationOverview,
    ModelFitView,
    RunProfileView,
    ScenarioView,
    ShiftView,
)
from app.db import repository as repo
from app.deps import ConstraintsQuery, ContextDep, SeedQuery
from app.errors import NotFound, ServiceError
from app.limits import INDEX_MAX
from app.rates import RegionReport
from app.services import rates

router = APIRouter(prefix="/dashboard", tags=["dashboard"])

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
#: the page's own files (anything else under /dashboard/static is a 404)
STATIC_FILES = {
    "dashboard.js": "text/javascript; charset=utf-8",
    "dashboard_rates.js": "text/javascript; charset=utf-8",
    "dashboard_sut.js": "text/javascript; charset=utf-8",
    "dashboard.css": "text/css; charset=utf-8",
}


@lru_cache(maxsize=1)
def plotly_js_path() -> Path:
    """plotly.min.js as shipped inside the installed plotly Python package."""
    import plotly

    path = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
    if not path.is_file():  # pragma: no cover - a broken plotly install
        raise ServiceError(f"plotly.min.js not found in the plotly package ({path})")
    return path


def _page(initial: dict[str, Any], status: int = 200) -> HTMLResponse:
    text = (STATIC_DIR / "dashboard.html").read_text(encoding="utf-8")
    state = html.escape(json.dumps(initial), quote=True)
    return HTMLResponse(text.replace("{{INITIAL_STATE}}", state), status_code=status)


# --------------------------------------------------------------------------- pages
@router.get("", response_class=HTMLResponse, summary="The dashboard page")
def dashboard_page() -> HTMLResponse:
    return _page({"catalogue": None})


@router.get("/catalogues/{catalogue_id}", response_class=HTMLResponse,
            summary="The dashboard page opened on one catalogue (404 page when unknown)")
def catalogue_page(catalogue_id: str, ctx: ContextDep,
                   scenario: Annotated[str | None, Query(max_length=20)] = None) -> HTMLResponse:
    try:
        with ctx.db.read_session() as s:
            repo.get_catalogue(s, catalogue_id)
    except NotFound as exc:
        return _page({"catalogue": None, "error": exc.message}, status=404)
    if scenario is not None and not scenario.isdigit():
        return _page({"catalogue": catalogue_id, "error": f"scenario must be a whole number "
                      f">= 0 (a scenario index), got {scenario!r}"}, status=422)
    return _page({"catalogue": catalogue_id,
                  "scenario": None if scenario is None else int(scenario)})


@lru_cache(maxsize=1)
def _plotly_gzip() -> tuple[bytes, str]:
    """plotly.min.js gzip-compressed once (4.8 MB → about 1.4 MB on the wire) and its ETag."""
    raw = plotly_js_path().read_bytes()
    return gzip.compress(raw, compresslevel=6, mtime=0), hashlib.sha256(raw).hexdigest()[:32]


@router.get("/static/plotly.min.js", summary="plotly.js from the installed plotly package",
            response_model=None)
def plotly_js(request: Request) -> Response:
    headers = {"Cache-Control": "public, max-age=86400", "Vary": "Accept-Encoding"}
    if "gzip" not in request.headers.get("accept-encoding", ""):
        return FileResponse(plotly_js_path(), media_type="text/javascript; charset=utf-8",
                            headers=headers)
    body, etag = _plotly_gzip()
    headers["ETag"] = f'"{etag}"'
    if request.headers.get("if-none-match") == headers["ETag"]:
        return Response(status_code=304, headers=headers)
    headers["Content-Encoding"] = "gzip"
    return Response(body, media_type="text/javascript; charset=utf-8", headers=headers)


@router.get("/static/{name}", summary="The dashboard's own script and style sheet")
def static_file(name: str) -> FileResponse:
    if name not in STATIC_FILES:
        raise NotFound(f"no static file {name!r}", field="path.name")
    return FileResponse(STATIC_DIR / name, media_type=STATIC_FILES[name],
                        headers={"Cache-Control": "no-cache"})


# --------------------------------------------------------------------------- JSON views
@router.get("/api/models/{model_id}/fit", response_model=ModelFitView,
            summary="Data against model: histograms with the GMM marginal densities, "
            "corner points")
def model_fit(model_id: str, ctx: ContextDep,
              dataset: Annotated[str | None, Query(max_length=64)] = None) -> ModelFitView:
    return views.model_fit(ctx, model_id, dataset or None)


@router.get("/api/models/{model_id}/shift", response_model=ShiftView,
            summary="Constrained against unconstrained samples for constraints typed in the "
            "page (not scored)")
def model_shift(
    model_id: str,
    ctx: ContextDep,
    constraints: ConstraintsQuery = "ttc<3",
    n: Annotated[int, Query(ge=1, le=views.PREVIEW_N_LIMIT)] = 1000,
    seed: SeedQuery = 0,
) -> ShiftView:
    return views.shift_preview(ctx, model_id, constraints, n, seed)


@router.get("/api/models/{model_id}/rates", response_model=RegionReport,
            summary="How often and how sure: P(A) of a region with its Monte Carlo and model "
            "intervals, the bootstrap replicates, and cut-ins per hour / per 10^6 km")
def model_rates(
    model_id: str,
    ctx: ContextDep,
    constraints: ConstraintsQuery = "ttc<3",
    seed: SeedQuery = 0,
) -> RegionReport:
    return rates.region_rates(ctx, model_id, constraints, seed)


@router.get("/api/catalogues/{catalogue_id}/shift", response_model=ShiftView,
            summary="Constrained (the catalogue's samples) against unconstrained model "
            "samples")
def catalogue_shift(catalogue_id: str, ctx: ContextDep) -> ShiftView:
    return views.catalogue_shift(ctx, catalogue_id)


@router.get("/api/catalogues/{catalogue_id}/criticality", response_model=CatalogueCriticalityView,
            summary="A catalogue's criticality: class counts, distributions of btn/a_req, "
            "ttr_true, impact speeds, r_dep at t_p and alarm time (counted in SQL), TTC "
            "against btn (thinned), the riskiest scenarios, P(A), sampler diagnostics")
def catalogue_criticality(catalogue_id: str, ctx: ContextDep) -> CatalogueCriticalityView:
    return views.catalogue_criticality(ctx, catalogue_id)


@router.get("/api/catalogues/{catalogue_id}/scenarios/{index}", response_model=ScenarioView,
            summary="One scenario: trajectories with the R157 driver's reacted ego, its "
            "criticality record, and r(t), TTC, WTTC, THW over time")
def scenario(catalogue_id: str, index: Annotated[int, PathParam(ge=0, le=INDEX_MAX)],
             ctx: ContextDep) -> ScenarioView:
    if index < 0:
        raise NotFound(f"scenario index must be >= 0, got {index}", field="path.index")
    return views.scenario(ctx, catalogue_id, index)


@router.get("/api/evaluations/{evaluation_id}", response_model=EvaluationOverview,
            summary="System under test: rate per hour with both intervals beside the careful "
            "driver's, failures, peak r_dep against btn")
def evaluation_overview(evaluation_id: str, ctx: ContextDep) -> EvaluationOverview:
    return evaluation_views.overview(ctx, evaluation_id)


@router.get("/api/evaluations/{evaluation_id}/runs/{run}", response_model=RunProfileView,
            summary="One run's speed, acceleration and r_dep, SUT beside the careful driver")
def evaluation_run(evaluation_id: str, run: Annotated[int, PathParam(ge=0, le=INDEX_MAX)],
                   ctx: ContextDep) -> RunProfileView:
    return evaluation_views.run_profile(ctx, evaluation_id, run)
