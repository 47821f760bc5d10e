"""The dashboard's JSON views, one function per view (docs/dashboard.md).

Each function reads what it needs through the service context, the repositories and
``app.domain``, and aggregates on the server (``app.dashboard.aggregate``), so the JSON
of every view is bounded whatever the size of the dataset or catalogue:

* ``model_fit``       data against model: per-parameter histogram + GMM marginal density,
                      and the pairwise (corner) points of data and model samples;
* ``shift_preview``   constrained against unconstrained for a model and constraints typed
                      in the page (samples drawn now, without scoring);
* ``catalogue_shift`` the same for a stored catalogue (its own samples);
* ``catalogue_risk``  a catalogue's risk distributions, P(A), seed and sampler diagnostics;
* ``scenario``        one scenario's trajectories and its risk/TTC/WTTC/THW over time.

Views of immutable things (models, finished catalogues, scenarios) are cached in memory
(``ViewCache``), keyed by what they depend on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from app import catalogues as catalogue_service
from app import domain, jsonconv
from app.cache import ViewCache
from app.context import ServiceContext
from app.dashboard.aggregate import (
    MAX_BINS,
    MAX_SCATTER,
    histogram,
    shared_edges,
    shares,
    thin_scatter,
)
from app.db import repository as repo
from app.db.models import CatalogueRow
from app.errors import Conflict, InvalidInput, NotFound

__all__ = [
    "CORNER_DEFAULT",
    "MAX_CORNER_POINTS",
    "PARAM_LABELS",
    "ViewCache",
    "catalogue_risk",
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
#: model draws behind the corner view and the unconstrained histograms
MODEL_DRAWS = 5000
#: points of a marginal density curve
DENSITY_POINTS = 120
#: bins of the per-parameter histograms
PARAM_BINS = 30
#: bins of the risk histograms over [0, 1]
RISK_BINS = 50
#: largest n of a constrained preview drawn from the page
PREVIEW_N_LIMIT = 5000
#: the model's unconstrained reference draws come from this seed (documented)
REFERENCE_SEED = 0


def _views(ctx: ServiceContext) -> ViewCache:
    """The views: small, bounded JSON-able results."""
    return ctx.cache("dashboard.views", 64)


def _column_cache(ctx: ServiceContext) -> ViewCache:
    """The catalogues' columns (n rows each): only the few most recent catalogues."""
    return ctx.cache("dashboard.columns", 4)


def _key(ctx: ServiceContext, *parts: Any) -> tuple[Any, ...]:
    return parts


# --------------------------------------------------------------------------- helpers
def split_constraints(text: str) -> list[str]:
    """Constraints typed in the page: ``"ttc<3; v_ego>=20"`` (``;``, ``,`` or ``&``
    separate them; blanks are dropped)."""
    parts = [p.strip() for p in text.replace("&", ";").replace(",", ";").split(";")]
    return [p for p in parts if p]


def _column(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name not in frame.columns:
        return np.empty(0)
    return np.asarray(pd.to_numeric(frame[name], errors="coerce"), dtype=np.float64)


def _evenly(n: int, m: int) -> np.ndarray:
    """``m`` evenly spaced indices of ``range(n)`` (all when n <= m), deterministic."""
    if n <= m:
        return np.arange(n)
    return (np.arange(m) * n) // m


def _points(frame: pd.DataFrame, names: Sequence[str], limit: int) -> dict[str, Any]:
    idx = _evenly(len(frame), limit)
    out: dict[str, Any] = {}
    for name in names:
        col = _column(frame, name)
        out[name] = jsonconv.plot_values(col[idx]) if col.size else []
    return {"n_total": len(frame), "n_shown": int(idx.size), "values": out}


def _model_and_row(ctx: ServiceContext, model_id: str) -> tuple[str, Any, Any]:
    mid = ctx.resolve_model_id(model_id)
    model = ctx.model(mid, field="path.model_id")
    with ctx.db.read_session() as s:
        row = repo.get_model(s, mid)
        s.expunge(row)
    return mid, model, row


def _reference_draws(ctx: ServiceContext, model_id: str, model: Any) -> pd.DataFrame:
    """The model's unconstrained reference: draws inside the physical bounds only."""
    def compute() -> pd.DataFrame:
        drawn = domain.sample(model, [], MODEL_DRAWS, REFERENCE_SEED, method="rejection")
        return drawn.params

    frame: pd.DataFrame = _views(ctx).get(_key(ctx, "reference", model_id), compute)
    return frame


# --------------------------------------------------------------------------- view 1
def model_fit(ctx: ServiceContext, model_id: str, dataset_id: str | None = None) -> dict[str, Any]:
    """Data against model: per parameter the data histogram and the GMM marginal density,
    and the corner points (data and plain model draws)."""
    mid, model, mrow = _model_and_row(ctx, model_id)
    ds_id = dataset_id or mrow.dataset_id
    with ctx.db.read_session() as s:
        drow = repo.get_dataset(s, ds_id, field="query.dataset")
        s.expunge(drow)

    def compute() -> dict[str, Any]:
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
            entry: dict[str, Any] = {
                "name": name,
                "label": PARAM_LABELS.get(name, name),
                "histogram": histogram(data, edges),
                "density": None,
            }
            if name in features:
                grid = np.linspace(edges[0] - pad, edges[-1] + pad, DENSITY_POINTS)
                dens = domain.marginal_density(model, name, grid)
                entry["density"] = {"x": jsonconv.plot_values(grid),
                                    "y": jsonconv.plot_values(dens)}
            else:
                entry["fixed"] = jsonconv.plot_values(getattr(model, "fixed_", {}).get(name))
            params.append(entry)
        return {
            "model": mid,
            "dataset": ds_id,
            "dataset_name": drow.name,
            "n_data": len(table),
            "n_components": mrow.n_components,
            "features": features,
            "parameters": params,
            "corner": {
                "names": list(domain.PARAM_NAMES),
                "labels": PARAM_LABELS,
                "default": list(CORNER_DEFAULT),
                "data": _points(table, domain.PARAM_NAMES, MAX_CORNER_POINTS),
                "model": _points(draws, domain.PARAM_NAMES, MAX_CORNER_POINTS),
            },
            "density_method": "exact marginal density of the fitted mixture",
        }

    result: dict[str, Any] = _views(ctx).get(_key(ctx, "fit", mid, ds_id, drow.data_hash), compute)
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


def _shift(reference: pd.DataFrame, constrained: pd.DataFrame) -> list[dict[str, Any]]:
    out = []
    for name in domain.PARAM_NAMES:
        ref = _column(reference, name)
        con = _column(constrained, name)
        edges = bins_for_both([ref, con], bins=PARAM_BINS)
        out.append({
            "name": name,
            "label": PARAM_LABELS.get(name, name),
            "unconstrained": histogram(ref, edges),
            "constrained": histogram(con, edges),
            "mean_unconstrained": jsonconv.plot_values(np.mean(ref)) if ref.size else None,
            "mean_constrained": jsonconv.plot_values(np.mean(con)) if con.size else None,
        })
    return out


def shift_preview(ctx: ServiceContext, model_id: str, constraint_text: str, n: int,
                  seed: int) -> dict[str, Any]:
    """Constrained against unconstrained for constraints typed in the page (no scoring)."""
    if not 1 <= n <= PREVIEW_N_LIMIT:
        raise InvalidInput(f"n must be between 1 and {PREVIEW_N_LIMIT}, got {n}",
                           field="query.n")
    texts = split_constraints(constraint_text)
    mid, model, _ = _model_and_row(ctx, model_id)
    constraints = domain.parse_constraints(texts, field="query.constraints")

    def compute() -> dict[str, Any]:
        reference = _reference_draws(ctx, mid, model)
        drawn = domain.sample(model, constraints, n, seed)
        return {
            "source": "preview",
            "model": mid,
            "constraints": texts,
            "n": n,
            "seed": seed,
            "n_reference": len(reference),
            "p_region": jsonconv.plot_values(drawn.p_region),
            "parameters": _shift(reference, drawn.params),
        }

    result: dict[str, Any] = _views(ctx).get(_key(ctx, "preview", mid, tuple(texts), n, seed),
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
    """A catalogue's stored rows as compact columns (read once per catalogue version and
    shared by the views): ``idx``, ``params`` (DataFrame), ``risk``, ``r_ind``, ``ttc``,
    ``min_ttr`` (float arrays; NaN = missing, inf kept) and ``evasion`` labels of the
    scored rows."""
    def compute() -> dict[str, Any]:
        names = list(domain.PARAM_NAMES)
        idx: list[int] = []
        params: list[list[float]] = []
        risk: list[float] = []
        r_ind: list[float] = []
        ttc: list[float] = []
        min_ttr: list[float] = []
        evasion: list[str | None] = []
        # streamed in batches: only the columns are kept, never the ORM rows
        with ctx.db.read_session() as s:
            for i, p, r, t, summary in repo.scenario_columns(s, crow.id):
                idx.append(i)
                p = p or {}
                summary = summary or {}
                params.append([_float(p.get(name)) for name in names])
                risk.append(_float(r))
                r_ind.append(_summary_value(summary, "risk_ind"))
                ttc.append(_float(t))
                ttr = _summary_value(summary, "min_ttr")
                if r is not None and summary.get("min_ttr") is None:
                    ttr = math.inf  # scored, and nothing collides: TTR is unbounded
                min_ttr.append(ttr)
                if r is not None:
                    evasion.append(_evasion_label(summary.get("min_ttr_evasion")))
        return {
            "idx": np.array(idx, dtype=np.int64),
            "params": pd.DataFrame(np.array(params, dtype=np.float64).reshape(-1, len(names)),
                                   columns=names),
            "risk": np.array(risk, dtype=np.float64),
            "r_ind": np.array(r_ind, dtype=np.float64),
            "ttc": np.array(ttc, dtype=np.float64),
            "min_ttr": np.array(min_ttr, dtype=np.float64),
            "evasion": evasion,
        }

    cols: dict[str, Any] = _column_cache(ctx).get(_key(ctx, "columns", *_version(crow)), compute)
    return cols


def _float(value: Any) -> float:
    """A stored number as float; None (or anything not a number) as NaN."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def catalogue_shift(ctx: ServiceContext, catalogue_id: str) -> dict[str, Any]:
    """Constrained (the catalogue's samples) against unconstrained (the model's draws
    inside the physical bounds)."""
    crow = _catalogue(ctx, catalogue_id)
    mid, model, _ = _model_and_row(ctx, crow.model_id)

    def compute() -> dict[str, Any]:
        constrained = _columns(ctx, crow)["params"]
        reference = _reference_draws(ctx, mid, model)
        return {
            "source": "catalogue",
            "catalogue": crow.id,
            "model": mid,
            "constraints": list(crow.spec.get("constraints", [])),
            "n": len(constrained),
            "seed": crow.seed,
            "n_reference": len(reference),
            "p_region": jsonconv.plot_values(jsonconv.decode(crow.p_region)),
            "parameters": _shift(reference, constrained),
        }

    result: dict[str, Any] = _views(ctx).get(_key(ctx, "cshift", *_version(crow)), compute)
    return result


# --------------------------------------------------------------------------- view 3
def _diagnostics(chunks: Sequence[Any]) -> dict[str, Any]:
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
    return {
        "chunks": len(per),
        "methods": methods,
        "acceptance_mean": float(np.mean(acc)) if acc else None,
        "acceptance_min": float(np.min(acc_min)) if acc_min else None,
        "tau_max": float(np.max(tau)) if tau else None,
        "ess_total": float(np.sum(ess)) if ess else None,
        "n_draws": float(np.sum(draws)) if draws else None,
        "warnings": warnings[:20],
    }


def _summary_value(summary: dict[str, Any], key: str) -> float:
    """A number of a stored summary (``"Infinity"`` → inf; missing → NaN)."""
    v = summary.get(key)
    if v == "Infinity":
        return math.inf
    if isinstance(v, int | float) and not isinstance(v, bool):
        return float(v)
    return math.nan


def _evasion_label(value: Any) -> str | None:
    """riskcore's label of the smallest TTR's evasion: None (nothing collides), "none"
    (no evasion works: unavoidable) or manoeuvre names joined by "+"."""
    if value is None:
        return None
    return "unavoidable" if value == "none" else str(value)


def catalogue_risk(ctx: ServiceContext, catalogue_id: str) -> dict[str, Any]:
    """A catalogue's risk distributions, P(A), n, seed and sampler diagnostics."""
    crow = _catalogue(ctx, catalogue_id)

    def compute() -> dict[str, Any]:
        info = catalogue_service.describe(ctx, catalogue_id)
        cols = _columns(ctx, crow)
        with ctx.db.read_session() as s:
            chunks = repo.chunk_rows(s, catalogue_id)
            diag = _diagnostics(chunks)
        idx, risk, r_ind = cols["idx"], cols["risk"], cols["r_ind"]
        ttc, min_ttr, evasion = cols["ttc"], cols["min_ttr"], cols["evasion"]
        scored = int(np.isfinite(risk).sum())
        risk_edges = shared_edges([], bins=RISK_BINS, span=(0.0, 1.0))
        ttr_edges = shared_edges([], bins=min(MAX_BINS, 31), span=(-0.05, 3.05))
        keep = thin_scatter(ttc, risk, MAX_SCATTER)
        return {
            "catalogue": info,
            "n_rows": int(idx.size),
            "n_scored": scored,
            "diagnostics": diag,
            "risk_hist": {"r_dep": histogram(risk, risk_edges),
                          "r_ind": histogram(r_ind, risk_edges)},
            "ttr_hist": histogram(min_ttr, ttr_edges),
            # the same rows the evasion chart calls "no collision" (stored as null or as
            # "Infinity"): one definition for both panels
            "n_no_collision": sum(1 for label in evasion if label is None),
            "evasion": shares(evasion, none_label="no collision"),
            "scatter": {
                "index": jsonconv.plot_values(idx[keep]),
                "ttc": jsonconv.plot_values(ttc[keep]),
                "risk": jsonconv.plot_values(risk[keep]),
                "n_total": int(idx.size),
                "n_plottable": int((np.isfinite(ttc) & np.isfinite(risk)).sum()),
                "n_shown": int(keep.size),
                "n_ttc_inf": int(np.sum(np.isinf(ttc))),
                "selection": "all points" if keep.size == int(
                    (np.isfinite(ttc) & np.isfinite(risk)).sum())
                else f"envelope grid + evenly spaced, at most {MAX_SCATTER} points",
            },
        }

    result: dict[str, Any] = _views(ctx).get(_key(ctx, "risk", *_version(crow)), compute)
    return result


# --------------------------------------------------------------------------- view 4
def _track(data: dict[str, Any]) -> dict[str, Any]:
    return {k: data.get(k) for k in ("id", "length", "width", "x", "y", "psi", "v")}


def scenario(ctx: ServiceContext, catalogue_id: str, index: int) -> dict[str, Any]:
    """One scenario of a catalogue: trajectories (top-down view) and the risk, TTC, WTTC
    and THW series over time (computed with riskcore on request, then cached)."""
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

    def compute() -> dict[str, Any]:
        sc, source = catalogue_service.stored_scenario(ctx, crow, row)
        if sc is None:
            raise Conflict(f"scenario {index} of catalogue {crow.id} has no trajectories: "
                           f"{row.error}", field="path.index")
        data = sc.to_dict()
        risk = domain.scenario_risk_series(sc)
        prov = data.get("provenance") or {}
        return {
            "catalogue": crow.id,
            "index": row.idx,
            "params": row.params,
            "trajectory_source": source,
            "ttc": jsonconv.plot_values(row.ttc),
            "risk": jsonconv.plot_values(row.risk),
            "lane_width": prov.get("lane_width"),
            "t": data["t"],
            "ego": _track(data["ego"]),
            "objects": [_track(o) for o in data.get("objects", [])],
            "summary": risk["summary"],
            "series": risk["series"],
        }

    result: dict[str, Any] = _views(ctx).get(_key(ctx, "scenario", crow.id, index),
                                        compute)
    return result
