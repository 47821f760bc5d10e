"""The dashboard's "system under test" section (issue 24): an evaluation's rate per hour
with both intervals beside the careful driver's, its failures, the SUT's peak r_dep
against btn, and one run's speed, acceleration and r_dep beside the careful driver's.

Thin views over ``app.services.evaluations``; plot data use null for gaps
(``jsonconv.plot_values``), the rest the service's JSON convention."""

from __future__ import annotations

import importlib
import math
from typing import Any

import numpy as np

from app import domain, jsonconv
from app.context import ServiceContext
from app.dashboard.schemas import (
    DriverProfile,
    EvaluationBrief,
    EvaluationOverview,
    EvaluationScatter,
    RunProfileView,
)
from app.errors import NotFound
from app.services import evaluations as service
from app.services import suts
from app.statuses import EvaluationStatus
from datasets import PARAM_NAMES

#: the careful driver the SUT is compared with (UN R157, JRC-FSM rule)
CAREFUL = "r157_cc"
#: how many runs the scatter shows: every collided run up to this many, then the others
SCATTER_RUNS = 400
#: rows of the failures list
FAILURES = 25


def reliability(collisions: Any, ess: Any) -> str | None:
    """Why an evaluation's intervals and acceleration vs naive Monte Carlo are not to be
    trusted (too few collisions or too small an effective sample size), or None: the
    findings ``few_collisions`` and ``low_ess`` of the campaign's own rule
    (``sampler.campaign.reliability``, which also gives the summary's ``warnings``).
    Without any collision the page shows the upper bound instead: not flagged here."""
    from sampler.campaign import MIN_COLLISIONS, MIN_ESS, interval_reasons

    why = interval_reasons(collisions, ess)
    if not why:
        return None
    # the rule, not a guess at which part failed: "ESS 5.31 (fewer than 10 collisions or
    # ESS below 10)" read as if 20 collisions were fewer than 10
    return ("unreliable: " + " and ".join(why) + f" (the intervals need at least "
            f"{MIN_COLLISIONS} collisions and an ESS of at least {MIN_ESS:g}) — run more "
            "(a larger n or the rhw stop rule)")


def _figures(summary: dict[str, Any] | None) -> dict[str, Any] | None:
    from sampler.campaign import summary_warnings as warnings

    if not summary:
        return None
    keys = ("p_collision", "rate_per_hour", "p_violation", "runs", "sut_runs", "pilot_runs",
            "skipped_runs", "collisions", "ess", "acceleration", "stop_reason")
    out = {k: summary.get(k) for k in keys}
    out["unreliable"] = reliability(summary.get("collisions"), summary.get("ess"))
    # every warning of the rule (the page shows only the flag above)
    out["warnings"] = warnings(summary)
    return out


def _sim_key(settings: dict[str, Any] | None) -> dict[str, Any]:
    """Simulator settings with the defaults filled in ({} and {"dt": 0.01} are the same
    simulator); settings that no longer parse are compared as given."""
    rs = importlib.import_module("riskcore.sut")
    try:
        return dict(rs.SimSettings.from_dict(dict(settings or {})).to_dict())
    except (TypeError, ValueError, KeyError):
        return dict(settings or {})


def careful_evaluation(ctx: ServiceContext, model_id: str, constraints: list[str],
                       settings: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The latest finished evaluation of the careful driver on the same model and region
    under the same simulator settings (``status`` "done", its ``figures``); else the
    latest one still queued or running (``figures`` null, its progress); else None."""
    best = None
    pending = None
    for row in service.list_all(ctx):
        spec = row.spec or {}
        if (row.sut == CAREFUL and row.model_id == model_id
                and list(spec.get("constraints", [])) == list(constraints)
                and _sim_key(spec.get("settings")) == _sim_key(settings)):
            if row.status == "done":
                best = row
            elif row.status in ("queued", "running"):
                pending = row
    if best is not None:
        return {"id": best.id, "status": best.status,
                "figures": _figures(jsonconv.decode(best.summary or {}))}
    if pending is not None:
        return {"id": pending.id, "status": pending.status, "figures": None,
                "runs_done": pending.runs_done, "runs_planned": pending.runs_planned}
    return None


def careful_request(st: EvaluationStatus) -> dict[str, Any]:
    """The body of ``POST /evaluations`` that evaluates the careful driver where the
    evaluation ``st`` (``service.describe``) was made: the same model, region, seed, number
    of draws or stop rule, and simulator settings."""
    spec = jsonconv.decode(st.spec)
    body: dict[str, Any] = {"sut": CAREFUL, "model": st.model,
                            "constraints": list(st.constraints), "seed": int(st.seed)}
    if spec.get("n") is not None:
        body["n"] = int(spec["n"])
    else:
        body["rhw"] = float(spec["rhw"])
        body["max_runs"] = int(spec["max_runs"])
    if spec.get("settings"):
        body["settings"] = dict(spec["settings"])
    return body


def failures_by_weight(ctx: ServiceContext, evaluation_id: str
                       ) -> tuple[int, int, list[dict[str, Any]]]:
    """(collided runs, how many of them are pilot runs, the first ``FAILURES`` of them):
    the collided runs of the counted chunks by weight, highest first (the runs that carry
    most of P), then those of the pilot chunks of a cross-entropy campaign by weight (its
    estimate leaves them out). Each record gains ``counted`` and ``share``: its weight over
    the sum of the weights of the counted collided runs (the shares add up to 1; null for
    a pilot run, and for every run until the evaluation is done)."""
    hit = (("collided", True),)
    pilots = service.pilot_chunks(ctx, evaluation_id)
    counted = service.RunFilter(flags=hit, skip_chunks=pilots)
    total, runs = service.page_runs(ctx, evaluation_id, counted, 0, FAILURES,
                                    order_by="weight", desc=True)
    whole = service.weight_sum(ctx, evaluation_id, counted)
    for r in runs:
        r["counted"] = True
        w = r.get("weight")
        r["share"] = w / whole if whole and w is not None else None
    n_pilot = 0
    if pilots:
        n_pilot, extra = service.page_runs(
            ctx, evaluation_id, service.RunFilter(flags=hit, chunks=pilots), 0,
            FAILURES - len(runs), order_by="weight", desc=True)
        runs += [{**r, "counted": False, "share": None} for r in extra]
    return total + n_pilot, n_pilot, runs


def overview(ctx: ServiceContext, evaluation_id: str) -> EvaluationOverview:
    """Status and figures of one evaluation, the careful driver's beside them, the
    failures list and the r_dep-against-btn scatter."""
    st = service.describe(ctx, evaluation_id)
    failures_total, failures_pilot, failures = failures_by_weight(ctx, evaluation_id)
    scatter: dict[str, Any] = {"run": [], "btn": [], "r_dep_peak": [], "impact_speed": [],
                               "collided": [], "vs_careful": [], "note": None}
    _, hits = service.page_runs(ctx, evaluation_id,
                                service.RunFilter(flags=(("collided", True),)), 0,
                                SCATTER_RUNS, order_by="run", desc=False)
    _, rest = service.page_runs(ctx, evaluation_id,
                                service.RunFilter(flags=(("collided", False),)), 0,
                                max(0, SCATTER_RUNS - len(hits)), order_by="run", desc=False)
    shown = hits + rest
    if shown:
        model = ctx.model(st.model)
        params = np.array([[float(r[k]) for k in PARAM_NAMES] for r in shown])
        crit = importlib.import_module("sampler.region").criticality_quantities(
            params, domain.model_lane_width(model), with_ttr=False)
        btn = np.asarray(crit["btn"], dtype=float)
        scatter.update(run=[int(r["run"]) for r in shown], btn=btn.tolist(),
                       r_dep_peak=[r.get("r_dep_peak") for r in shown],
                       impact_speed=[r.get("impact_speed") for r in shown],
                       collided=[bool(r.get("collided")) for r in shown],
                       vs_careful=[r.get("vs_careful") for r in shown])
        if all(v is None or (isinstance(v, float) and math.isnan(v))
               for v in scatter["r_dep_peak"]):
            # the page then plots the impact speed against btn instead, and says why
            scatter["note"] = ("r_dep of the SUT's drive not computed, the evaluation "
                               "was made without risk: true")
    return EvaluationOverview(
        evaluation=EvaluationBrief(**{k: getattr(st, k) for k in EvaluationBrief.model_fields}),
        figures=_figures(None if st.summary is None else jsonconv.decode(st.summary)),
        careful=careful_evaluation(ctx, st.model, list(st.constraints),
                                   jsonconv.decode(st.spec).get("settings")),
        careful_request=careful_request(st),
        failures_total=failures_total,
        failures_pilot=failures_pilot,
        failures=jsonconv.encode(failures),
        scatter=EvaluationScatter(**jsonconv.plot_values(scatter)),
    )


def run_profile(ctx: ServiceContext, evaluation_id: str, run: int) -> RunProfileView:
    """One run driven again by the SUT and by the careful driver, with profiles: time,
    the ego's speed and acceleration, r_dep (null where not computed)."""
    st = service.describe(ctx, evaluation_id)
    rec = service.run_by_index(ctx, evaluation_id, run)
    if rec is None:
        raise NotFound(f"evaluation {evaluation_id} has no simulated run {run}",
                       field="path.run")
    model = ctx.model(st.model)
    lane = domain.model_lane_width(model)
    params = {k: float(rec[k]) for k in PARAM_NAMES}
    scenario = service.rebuild(params, lane, st.seed, run, evaluation_id)
    if scenario is None:
        raise NotFound(f"run {run}: the builder refuses its vector", field="path.run")
    rs = importlib.import_module("riskcore.sut")
    batch = rs.CutInBatch.from_scenarios([scenario], lane_width=lane)
    seeds = np.array([int(rec["seed"])], dtype=np.uint64)
    spec = jsonconv.decode(st.spec)
    sim = rs.SimSettings.from_dict(spec["settings"]) if spec.get("settings") else None
    entry = suts.resolve(st.sut, allow_import=False, field="sut")
    drivers: dict[str, DriverProfile] = {}
    for label, factory in (("sut", entry.factory(spec.get("sut_params") or {})),
                           ("careful", suts.registry().entries[CAREFUL].factory())):
        runs = _simulate(rs, factory(), batch, seeds, sim)
        prof = runs.profiles or {}
        t = np.asarray(prof.get("t", []), dtype=float)
        r_dep = prof.get("r_dep")
        drivers[label] = DriverProfile(**jsonconv.plot_values({
            "name": str(getattr(factory, "name", label)),
            "t": t.tolist(),
            "v": np.asarray(prof.get("v", [[]]))[0].tolist(),
            "a": np.asarray(prof.get("a", [[]]))[0].tolist(),
            "t_risk": None if r_dep is None else batch.t.tolist(),
            "r_dep": None if r_dep is None else np.asarray(r_dep)[0].tolist(),
            "collided": bool(runs.collided[0]),
            "impact_speed": float(runs.impact_speed[0]),
            "min_gap": float(runs.min_gap[0]),
        }))
    return RunProfileView(run=jsonconv.encode(rec), drivers=drivers)


def _simulate(rs: Any, sut: Any, batch: Any, seeds: Any, sim: Any) -> Any:
    try:
        return rs.simulate(sut, batch, seeds=seeds, settings=sim, profiles=True, risk=True)
    except (NotImplementedError, rs.SutError):
        # the risk of the drive is not available (yet): the profiles without it; a
        # problem of the run itself raises again here
        return rs.simulate(sut, batch, seeds=seeds, settings=sim, profiles=True)
