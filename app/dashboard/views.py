"""The dashboard's JSON views, one function per view (docs/dashboard.md).

Each function reads what it needs through the service context, the repositories and
``app.domain``, and aggregates on the server (``app.dashboard.aggregate``), so the JSON
of every view is bounded whatever the size of the dataset or catalogue:

* ``model_fit``       data against model: per-parameter histogram + GMM marginal density,
                      and the pairwise (corner) points of data and model samples;
* ``shift_preview``   constrained against unconstrained for a model and constraints typed
                      in the page (samples drawn now, without scoring);
* ``catalogue_shift`` the same for a stored catalogue (its own samples);
* ``catalogue_criticality`` a catalogue's criticality: class counts, distributions of the
                      record's fields (counted in SQL, ``app.dashboard.queries``), TTC
                      against btn, the riskiest scenarios, P(A) and sampler diagnostics;
* ``scenario``        one scenario's trajectories, its criticality record, and Wagner's
                      risk over time for the scripted and the R157 driver's ego.

Views of immutable things (models, finished catalogues, scenarios) are cached in memory
(``ViewCache``), keyed by what they depend on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from app import domain, jsonconv
from app.cache import ViewCache
from app.context import ServiceContext
from app.dashboard import queries
from app.dashboard.aggregate import (
    MAX_SCATTER,
    histogram,
    nice_edges,
    shared_edges,
    thin_scatter,
)
from app.dashboard.schemas import (
    CatalogueCriticalityView,
    ClassCount,
    CornerPoints,
    CornerView,
    CriticalityScatter,
    DensityCurve,
    Diagnostics,
    DriverImpact,
    FitParameter,
    HistogramView,
    ModelFitView,
    PlotValues,
    ProfilesView,
    RiskAtPerception,
    ScenarioView,
    ShiftParameter,
    ShiftView,
    TopScenario,
    TrackView,
)
from app.db import repository as repo
from app.db.models import CatalogueRow
from app.errors import Conflict, InvalidInput, NotFound
from app.services import catalogues as catalogue_service
from app.services.models import model_and_row
from app.services.sampling import (
    MODEL_DRAWS,
    REFERENCE_SEED,
    reference_draws,
    split_constraints,
)
from app.statuses import catalogue_status_plain

__all__ = [
    "CLASS_LABELS",
    "CORNER_DEFAULT",
    "MAX_CORNER_POINTS",
    "PARAM_LABELS",
    "ViewCache",
    "catalogue_criticality",
    "catalogue_shift",
    "model_fit",
    "scenario",
    "shift_preview",
    "split_constraints",
]

#: axis labels with units of the parameters (DESIGN.md)
PARAM_LABELS: dict[str, str] = {
    "p_y1": "p_y1 yaw-rate amplitude [rad/s]",
    "p_t": "p_t half lane-change time [s]",
    "p_a1": "p_a1 pulse acceleration [m/s²]",
    "p_a2": "p_a2 pulse start [s]",
    "p_a3": "p_a3 pulse duration [s]",
    "p_v0": "p_v0 cutter speed at t=0 [m/s]",
    "dv": "dv closing speed at crossing [m/s]",
    "gap": "gap at crossing [m]",
}
#: parameters of the corner view the page shows first
CORNER_DEFAULT = ("p_t", "p_v0", "dv", "gap")
#: points per group (data, model samples) in the corner view
MAX_CORNER_POINTS = 400
#: points of a marginal density curve
DENSITY_POINTS = 120
#: bins of the per-parameter histograms
PARAM_BINS = 30
#: edges of the r_dep-at-t_p histograms: [0, 1e-8), then half decades up to 1. r_dep at
#: t_p is exactly 0 for most cut-ins and spans 1e-7 ... 1 for the rest, so 20 bins of 0.05
#: showed one spike at 0 (issue 25)
RISK_LOG_EDGES: tuple[float, ...] = (0.0, *(10.0 ** (k / 2) for k in range(-16, 1)))
#: largest number of bins of the other criticality histograms (``nice_edges``)
CRITICALITY_BINS = 40
#: largest number of bins of the impact-speed histograms (three drivers side by side:
#: 40 bins made a comb of thin bars)
IMPACT_BINS = 20
#: rows of the "riskiest scenarios" table
TOP_N = 10
#: what each criticality class means, for the page (docs/criticality.md)
CLASS_LABELS: dict[str, str] = {
    "no_conflict": "no conflict (no collision without reaction)",
    "preventable": "preventable (careful driver avoids it)",
    "unpreventable": "unpreventable (careful driver collides; some manoeuvre avoids it)",
    "unavoidable": "unavoidable (nothing avoids it)",
}
#: the reference drivers whose impact speeds view 3 shows
DRIVER_LABELS: dict[str, str] = {
    "none": "no reaction (scripted ego)",
    "r157_cc": "R157 careful driver",
    "rss": "RSS response",
}
#: largest n of a constrained preview drawn from the page
PREVIEW_N_LIMIT = 5000


def _views(ctx: ServiceContext) -> ViewCache:
    """The views: small, bounded JSON-able results."""
    return ctx.cache("dashboard.views", 64)


def _column_cache(ctx: ServiceContext) -> ViewCache:
    """The catalogues' columns (n rows each): only the few most recent catalogues."""
    return ctx.cache("dashboard.columns", 4)


def _key(ctx: ServiceContext, *parts: Any) -> tuple[Any, ...]:
    return parts


# --------------------------------------------------------------------------- helpers
def _column(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name not in frame.columns:
        return np.empty(0)
    return np.asarray(pd.to_numeric(frame[name], errors="coerce"), dtype=np.float64)


def _evenly(n: int, m: int) -> np.ndarray:
    """``m`` evenly spaced indices of ``range(n)`` (all when n <= m), deterministic."""
    if n <= m:
        return np.arange(n)
    return (np.arange(m) * n) // m


def _points(frame: pd.DataFrame, names: Sequence[str], limit: int) -> CornerPoints:
    idx = _evenly(len(frame), limit)
    out: dict[str, PlotValues] = {}
    for name in names:
        col = _column(frame, name)
        out[name] = jsonconv.plot_values(col[idx]) if col.size else []
    return CornerPoints(n_total=len(frame), n_shown=int(idx.size), values=out)


# --------------------------------------------------------------------------- view 1
def model_fit(ctx: ServiceContext, model_id: str, dataset_id: str | None = None) -> ModelFitView:
    """Data against model: per parameter the data histogram and the GMM marginal density,
    and the corner points (data and plain model draws)."""
    mid, model, mrow = model_and_row(ctx, model_id)
    ds_id = dataset_id or mrow.dataset_id
    with ctx.db.read_session() as s:
        drow = repo.get_dataset(s, ds_id, field="query.dataset")
        s.expunge(drow)

    def compute() -> ModelFitView:
        try:
            table = ctx.dataset_table(drow)
        except OSError as exc:
            raise InvalidInput(f"dataset {ds_id!r} has no readable table: {exc}",
                               field="query.dataset") from None
        draws = domain.model_draws(model, MODEL_DRAWS, REFERENCE_SEED)
        features = domain.model_features(model)
        params = []
        for name in domain.PARAM_NAMES:
            data = _column(table, name)
            edges = shared_edges([data], bins=PARAM_BINS, quantiles=(0.0, 1.0))
            pad = 0.15 * (edges[-1] - edges[0])
            density = fixed = None
            if name in features:
                grid = np.linspace(edges[0] - pad, edges[-1] + pad, DENSITY_POINTS)
                dens = domain.marginal_density(model, name, grid)
                density = DensityCurve(x=jsonconv.plot_values(grid),
                                       y=jsonconv.plot_values(dens))
            else:
                fixed = jsonconv.plot_values(getattr(model, "fixed_", {}).get(name))
            params.append(FitParameter(name=name, label=PARAM_LABELS.get(name, name),
                                       histogram=HistogramView(**histogram(data, edges)),
                                       density=density, fixed=fixed))
        return ModelFitView(
            model=mid,
            dataset=ds_id,
            dataset_name=drow.name,
            n_data=len(table),
            n_components=mrow.n_components,
            features=features,
            parameters=params,
            corner=CornerView(
                names=list(domain.PARAM_NAMES),
                labels=PARAM_LABELS,
                default=list(CORNER_DEFAULT),
                data=_points(table, domain.PARAM_NAMES, MAX_CORNER_POINTS),
                model=_points(draws, domain.PARAM_NAMES, MAX_CORNER_POINTS),
            ),
            density_method="exact marginal density of the fitted mixture",
        )

    result: ModelFitView = _views(ctx).get(_key(ctx, "fit", mid, ds_id, drow.data_hash),
                                           compute)
    return result


# --------------------------------------------------------------------------- view 2
def bins_for_both(samples: Sequence[np.ndarray], bins: int,
                  quantiles: tuple[float, float] = (0.005, 0.995)) -> np.ndarray:
    """Edges whose range holds every sample's own central range (its ``quantiles``): a
    small constrained sample is not squeezed into the edge bins of the much larger
    unconstrained one, whose pooled quantiles would otherwise set the range alone."""
    each = [shared_edges([s], bins=bins, quantiles=quantiles)
            for s in samples if np.isfinite(np.asarray(s, dtype=float)).any()]
    if not each:
        return shared_edges([], bins=bins)
    return shared_edges([], bins=bins, span=(min(float(e[0]) for e in each),
                                             max(float(e[-1]) for e in each)))


def _shift(reference: pd.DataFrame, constrained: pd.DataFrame) -> list[ShiftParameter]:
    out = []
    for name in domain.PARAM_NAMES:
        ref = _column(reference, name)
        con = _column(constrained, name)
        edges = bins_for_both([ref, con], bins=PARAM_BINS)
        out.append(ShiftParameter(
            name=name,
            label=PARAM_LABELS.get(name, name),
            unconstrained=HistogramView(**histogram(ref, edges)),
            constrained=HistogramView(**histogram(con, edges)),
            mean_unconstrained=jsonconv.plot_values(np.mean(ref)) if ref.size else None,
            mean_constrained=jsonconv.plot_values(np.mean(con)) if con.size else None,
        ))
    return out


def shift_preview(ctx: ServiceContext, model_id: str, constraint_text: str, n: int,
                  seed: int) -> ShiftView:
    """Constrained against unconstrained for constraints typed in the page (no scoring)."""
    if not 1 <= n <= PREVIEW_N_LIMIT:
        raise InvalidInput(f"n must be between 1 and {PREVIEW_N_LIMIT}, got {n}",
                           field="query.n")
    texts = split_constraints(constraint_text)
    mid, model, _ = model_and_row(ctx, model_id)
    constraints = domain.parse_constraints(texts, field="query.constraints")

    def compute() -> ShiftView:
        reference = reference_draws(ctx, mid, model)
        drawn = domain.sample(model, constraints, n, seed)
        return ShiftView(
            source="preview",
            model=mid,
            constraints=texts,
            n=n,
            seed=seed,
            n_reference=len(reference),
            p_region=jsonconv.plot_values(drawn.p_region),
            parameters=_shift(reference, drawn.params),
        )

    result: ShiftView = _views(ctx).get(_key(ctx, "preview", mid, tuple(texts), n, seed),
                                        compute)
    return result


def _catalogue(ctx: ServiceContext, catalogue_id: str) -> CatalogueRow:
    with ctx.db.read_session() as s:
        row = repo.get_catalogue(s, catalogue_id)
        s.expunge(row)
    return row


def _version(row: CatalogueRow) -> tuple[Any, ...]:
    return (row.id, row.status, row.updated_at.isoformat() if row.updated_at else None)


def _columns(ctx: ServiceContext, crow: CatalogueRow) -> dict[str, Any]:
    """A catalogue's stored parameter vectors as compact columns (read once per catalogue
    version): ``idx`` and ``params`` (DataFrame; NaN = missing)."""
    def compute() -> dict[str, Any]:
        names = list(domain.PARAM_NAMES)
        idx: list[int] = []
        params: list[list[float]] = []
        # streamed in batches: only the columns are kept, never the ORM rows
        with ctx.db.read_session() as s:
            for i, p, _, _, _ in repo.scenario_columns(s, crow.id):
                idx.append(i)
                p = p or {}
                params.append([_float(p.get(name)) for name in names])
        return {
            "idx": np.array(idx, dtype=np.int64),
            "params": pd.DataFrame(np.array(params, dtype=np.float64).reshape(-1, len(names)),
                                   columns=names),
        }

    cols: dict[str, Any] = _column_cache(ctx).get(_key(ctx, "columns", *_version(crow)), compute)
    return cols


def _float(value: Any) -> float:
    """A stored number as float; None (or anything not a number) as NaN."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def catalogue_shift(ctx: ServiceContext, catalogue_id: str) -> ShiftView:
    """Constrained (the catalogue's samples) against unconstrained (the model's draws
    inside the physical bounds)."""
    crow = _catalogue(ctx, catalogue_id)
    mid, model, _ = model_and_row(ctx, crow.model_id)

    def compute() -> ShiftView:
        constrained = _columns(ctx, crow)["params"]
        reference = reference_draws(ctx, mid, model)
        return ShiftView(
            source="catalogue",
            catalogue=crow.id,
            model=mid,
            constraints=list(crow.spec.get("constraints", [])),
            n=len(constrained),
            seed=crow.seed,
            n_reference=len(reference),
            p_region=jsonconv.plot_values(jsonconv.decode(crow.p_region)),
            parameters=_shift(reference, constrained),
        )

    result: ShiftView = _views(ctx).get(_key(ctx, "cshift", *_version(crow)), compute)
    return result


# --------------------------------------------------------------------------- view 3
def _diagnostics(chunks: Sequence[Any]) -> Diagnostics:
    """Sampler diagnostics over a catalogue's chunks (each chunk is sampled on its own)."""
    per = [jsonconv.decode(c.diagnostics or {}).get("sampler") or {} for c in chunks]
    methods = sorted({str(d.get("method")) for d in per if d.get("method")})

    def values(key: str) -> list[float]:
        out = []
        for d in per:
            v = d.get(key)
            if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
                out.append(float(v))
        return out

    acc = values("acceptance_rate") + values("acceptance_mean")
    acc_min = values("acceptance_min") + values("acceptance_rate")
    tau = values("tau_max")
    ess = values("ess")
    draws = values("n_draws")
    warnings: list[str] = []
    for d in per:
        warnings.extend(str(w) for w in d.get("warnings", []) or [])
    return Diagnostics(
        chunks=len(per),
        methods=methods,
        acceptance_mean=float(np.mean(acc)) if acc else None,
        acceptance_min=float(np.min(acc_min)) if acc_min else None,
        tau_max=float(np.max(tau)) if tau else None,
        ess_total=float(np.sum(ess)) if ess else None,
        n_draws=float(np.sum(draws)) if draws else None,
        warnings=warnings[:20],
    )


def _edges_from(session: Any, catalogue_id: str, cols: Sequence[Any],
                where: Sequence[Any] = (), at_least: float = 1.0) -> np.ndarray:
    """Round-number edges from 0 to the largest finite value of ``cols`` (at least
    ``at_least``): the fields of view 3 are all >= 0."""
    hi = at_least
    for col in cols:
        rng = queries.finite_range(session, catalogue_id, col, where)
        if rng is not None:
            hi = max(hi, rng[1])
    return nice_edges(0.0, hi, CRITICALITY_BINS)


def _scatter(session: Any, catalogue_id: str) -> CriticalityScatter:
    """TTC against btn, thinned (the envelope keeps the highest btn of each cell)."""
    cols = queries.scatter_columns(session, catalogue_id)
    idx, ttc, btn, cls = cols["idx"], cols["ttc"], cols["btn"], cols["class"]
    keep = thin_scatter(ttc, btn, MAX_SCATTER)
    plottable = int((np.isfinite(ttc) & np.isfinite(btn)).sum())
    return CriticalityScatter(
        index=[int(i) for i in idx[keep]],
        ttc=[float(v) for v in ttc[keep]],
        btn=[float(v) for v in btn[keep]],
        cls=[str(cls[i]) for i in keep],
        n_total=int(idx.size),
        n_plottable=plottable,
        n_shown=int(keep.size),
        n_ttc_inf=int(np.isinf(ttc).sum()),
        n_btn_inf=int(np.isinf(btn).sum()),
        selection="all points" if keep.size == plottable
        else f"envelope grid + evenly spaced, at most {MAX_SCATTER} points",
    )


def catalogue_criticality(ctx: ServiceContext, catalogue_id: str) -> CatalogueCriticalityView:
    """A catalogue's criticality (class counts, the record's distributions, TTC against
    btn, the riskiest scenarios), P(A), n, seed and sampler diagnostics. Every histogram is
    counted in SQL."""
    from riskcore.criticality import CLASSES, CriticalitySettings

    crow = _catalogue(ctx, catalogue_id)
    decel_max = CriticalitySettings().decel_max

    def compute() -> CatalogueCriticalityView:
        info = catalogue_service.describe(ctx, catalogue_id)
        col = queries.column
        scored = col("class").is_not(None)
        with ctx.db.read_session() as s:
            diag = _diagnostics(repo.chunk_rows(s, catalogue_id))
            counts = repo.class_counts(s, catalogue_id)
            n_rows = sum(counts.values())
            n_scored = n_rows - counts.get("unscored", 0)
            btn = HistogramView(**queries.column_histogram(
                s, catalogue_id, col("btn"), _edges_from(s, catalogue_id, [col("btn")]),
                [scored]))
            ttr = HistogramView(**queries.column_histogram(
                s, catalogue_id, col("ttr_true"),
                _edges_from(s, catalogue_id, [col("ttr_true")]), [scored]))
            speeds = [(d, col(f"{d}_impact_speed"), col(f"{d}_collision").is_(True))
                      for d in DRIVER_LABELS]
            hi = 1.0
            for _, c, hit in speeds:
                rng = queries.finite_range(s, catalogue_id, c, [hit])
                hi = max(hi, rng[1]) if rng else hi
            speed_edges = nice_edges(0.0, hi, IMPACT_BINS)
            impact = [DriverImpact(driver=d, label=DRIVER_LABELS[d],
                                   histogram=HistogramView(**queries.column_histogram(
                                       s, catalogue_id, c, speed_edges, [hit])))
                      for d, c, hit in speeds]
            risk_edges = np.asarray(RISK_LOG_EDGES)
            r_dep_tp = RiskAtPerception(**{
                name: HistogramView(**queries.column_histogram(s, catalogue_id, col(field),
                                                               risk_edges, [scored]))
                for name, field in (("scripted", "r_dep_tp"), ("r157", "r_dep_tp_r157"))})
            alarm = HistogramView(**queries.column_histogram(
                s, catalogue_id, col("alarm_time"),
                _edges_from(s, catalogue_id, [col("alarm_time")]), [scored]))
            scatter = _scatter(s, catalogue_id)
            top = queries.top_rows(s, catalogue_id, TOP_N)
        return CatalogueCriticalityView(
            catalogue=catalogue_status_plain(info),
            n_rows=n_rows,
            n_scored=n_scored,
            diagnostics=diag,
            classes=[ClassCount(name=c, label=CLASS_LABELS[c], count=counts.get(c, 0))
                     for c in CLASSES],
            n_unscored=counts.get("unscored", 0),
            decel_max=decel_max,
            btn=btn,
            ttr_true=ttr,
            impact_speed=impact,
            r_dep_tp=r_dep_tp,
            alarm_time=alarm,
            scatter=scatter,
            top=[TopScenario.model_validate(row) for row in top],
        )

    result: CatalogueCriticalityView = _views(ctx).get(
        _key(ctx, "criticality", *_version(crow)), compute)
    return result


# --------------------------------------------------------------------------- view 4
def _track(data: dict[str, Any]) -> TrackView:
    """A track of a scenario's JSON form (``ConcreteScenario.to_dict``) for the page."""
    return TrackView(id=data.get("id"), length=data.get("length"), width=data.get("width"),
                     x=data.get("x"), y=data.get("y"), psi=data.get("psi"), v=data.get("v"))


def _profiles(sc: Any) -> tuple[ProfilesView | None, str | None]:
    """Wagner's r(t) for the scripted and the R157 driver's ego and the R157 ego's track
    (``riskcore.criticality.criticality_profiles``, computed for this one scenario), as
    plot data; or None and why not."""
    from riskcore import RiskcoreError
    from riskcore.criticality import criticality_profiles

    try:
        prof = criticality_profiles(sc)
    except RiskcoreError as exc:
        return None, str(exc)
    return ProfilesView.model_validate(jsonconv.plot_values(prof)), None


def scenario(ctx: ServiceContext, catalogue_id: str, index: int) -> ScenarioView:
    """One scenario of a catalogue: trajectories (top-down view, with the R157 driver's
    reacted ego), its stored criticality record, and the risk, TTC, WTTC and THW series
    over time for the scripted ego and r(t) for the R157 ego (computed with riskcore on
    request, then cached)."""
    crow = _catalogue(ctx, catalogue_id)
    with ctx.db.read_session() as s:
        found = repo.scenario_batch(s, catalogue_id, index - 1, 1)
        s.expunge_all()
    if not found or found[0].idx != index:
        raise NotFound(f"catalogue {catalogue_id!r} has no scenario {index} (it has "
                       f"{crow.n} scenarios, indices 0 … {crow.n - 1}"
                       f"{'' if crow.status == 'done' else '; it is still ' + crow.status})",
                       field="path.index")
    row = found[0]

    def compute() -> ScenarioView:
        sc, source = catalogue_service.stored_scenario(ctx, crow, row)
        if sc is None:
            raise Conflict(f"scenario {index} of catalogue {crow.id} has no trajectories: "
                           f"{row.error}", field="path.index")
        data = sc.to_dict()
        risk = domain.scenario_risk_series(sc)
        prov = data.get("provenance") or {}
        profiles, profiles_error = _profiles(sc)
        ego = _track(data["ego"])
        if profiles is not None:
            # the R157 driver's ego is the same car as the scripted one: its size, so the
            # page can draw its box (issue 25: null sizes made view 4 skip it)
            profiles.r157_ego.length, profiles.r157_ego.width = ego.length, ego.width
        return ScenarioView(
            catalogue=crow.id,
            index=row.idx,
            params=row.params,
            trajectory_source=source,
            lane_width=prov.get("lane_width"),
            t=data["t"],
            ego=ego,
            objects=[_track(o) for o in data.get("objects", [])],
            record=catalogue_service.record_of(row),
            summary=jsonconv.encode(risk["summary"]),
            series=risk["series"],
            profiles=profiles,
            profiles_error=profiles_error,
        )

    result: ScenarioView = _views(ctx).get(_key(ctx, "scenario", crow.id, index), compute)
    return result
