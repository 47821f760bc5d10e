"""Hashes of sampler outputs with fixed seeds, to show a refactoring of the sampler's long
functions changed nothing bit for bit (issue 26 items 2 and 9; the HTTP/CLI side is
scripts/behaviour_snapshot.py, which takes minutes).

    .venv/bin/python scripts/golden.py record  /tmp/golden.json
    .venv/bin/python scripts/golden.py compare /tmp/golden.json

Cases: ``region_limit_state`` of several regions (one quantity, kinematic only, flat
criticality, layered, support class) evaluated on fixed draws; ``subset_simulation`` on
``ttc<3``; ``build_scenario`` on fixed vectors (with and without a duration, and its
refusals); ``sample()`` with rejection and mcmc; the campaign's SUT runner (acc, with the
careful driver) on fixed draws. Each output's bytes are hashed with
SHA-256; ``compare`` prints the cases whose hash changed and exits 1 if any did.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from anywhere

from datasets import PARAM_NAMES
from datasets.embedded import default_parameter_table
from sampler import CutInGMM, sample
from sampler.methods.probability import PRegionEstimator
from sampler.methods.rare import rare_probability
from sampler.methods.subset import region_limit_state, subset_simulation
from sampler.model.io import model_from_dict, model_to_dict
from sampler.region.btn_bound import a_req_bound
from sampler.region.constraints import QUANTITY_NAMES, Region, derive
from sampler.region.criticality import criticality_quantities
from sampler.scenario import build_scenario
from sampler.scenario.record import score_vector
from sampler.scenario.scoring import score_samples

REGIONS = [["ttc<3"], ["ttc<2", "thw<1"], ["btn>0.5"], ["ttc<4", "btn>0.3"],
           ["ttc<5", "gap<40", "ttr_true<3", "btn>0.05"], ["ttc<3", "support<=near"],
           ["r157_impact_speed>0"], ["a_req>=3", "btn<=0.9"]]


def _digest(*arrays: Any) -> str:
    h = hashlib.sha256()
    for a in arrays:
        if isinstance(a, np.ndarray | float | int):
            h.update(np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes())
        else:
            h.update(json.dumps(a, sort_keys=True, default=str).encode())
    return h.hexdigest()


def _no_clock(obj: Any) -> Any:
    """``obj`` without its wall-clock figures (keys naming seconds), recursively."""
    if isinstance(obj, dict):
        return {k: _no_clock(v) for k, v in obj.items() if "seconds" not in str(k)}
    if isinstance(obj, list | tuple):
        return [_no_clock(v) for v in obj]
    return obj


def _note(calls: list[tuple[int, int]], done: int, total: int) -> None:
    calls.append((done, total))


def _cases(model: CutInGMM) -> dict[str, Callable[[], str]]:
    cases: dict[str, Callable[[], str]] = {}
    z = model.sample_z(3000, np.random.default_rng(3))
    for cons in REGIONS:
        region = Region.from_constraints(cons, lane_width=model.lane_width_)

        def g_case(region: Region = region) -> str:
            return _digest(region_limit_state(model, region, np.random.default_rng(0))(z))
        cases["limit_state " + " & ".join(cons)] = g_case

    def subset_case() -> str:
        region = Region.from_constraints(["ttc<3"], lane_width=model.lane_width_)
        r = subset_simulation(model, region_limit_state(model, region,
                                                        np.random.default_rng(5)), 5,
                              n_per_level=500)
        return _digest(r.probability, r.cov, r.cov_upper, r.n_evaluations, r.thresholds,
                       r.conditional, r.gamma, r.delta, r.z)  # not r.seconds (wall clock)
    cases["subset_simulation ttc<3"] = subset_case

    x = model.params_matrix(model.sample(40, np.random.default_rng(11)))
    rows = [dict(zip(PARAM_NAMES, map(float, r), strict=True)) for r in x]

    def build_case() -> str:
        out = []
        for row in rows:
            for kw in ({}, {"duration": 20.0}, {"lead_in": 0.0, "dt": 0.05},
                       {"lane_width": 3.2, "ego_size": (4.0, 1.7), "seed": 3}):
                try:
                    s = build_scenario(row, **kw)
                except Exception as exc:  # a refusal is an output too
                    out.append(f"{type(exc).__name__}: {exc}")
                    continue
                out.append(_digest(s.t, *(getattr(o, k) for o in (s.ego, *s.objects)
                                          for k in ("x", "y", "psi", "v", "a")),
                                   s.provenance, s.params))
        for bad in ({"p_y1": 0.0}, {"dv": -40.0}):
            try:
                build_scenario({**rows[0], **bad})
            except Exception as exc:
                out.append(f"{type(exc).__name__}: {exc}")
        return _digest(out)
    cases["build_scenario"] = build_case

    for method in ("rejection", "mcmc"):
        def sample_case(method: str = method) -> str:
            s = sample(model, ["ttc<3"], n=200, seed=7, method=method)
            return _digest(np.asarray(s.params if hasattr(s, "params") else s))
        cases[f"sample {method}"] = sample_case

    def sample_support_case() -> str:
        s = sample(model, ["ttc<4", "support<=near"], n=100, seed=9, method="rejection",
                   use_envelope=False)
        return _digest(np.asarray(s.params), np.asarray(s.derived), s.log_density,
                       s.exposure_weights, s.diagnostics.get("pilot"), s.support)
    cases["sample rejection support, no envelope"] = sample_support_case

    def fit_case() -> str:
        return _digest(model.weights_, model.means_, model.covariances_, model.bic_curve_,
                       model.fit_report_, model.training_, model.support_)
    cases["CutInGMM.fit"] = fit_case

    xc = model.params_matrix(model.sample(300, np.random.default_rng(13)))
    xc[:3, 0] = (0.0, np.nan, -xc[2, 0])  # not a cut-in, not finite, the other side

    def crit_case(baseline: bool, with_ttr: bool) -> str:
        q = criticality_quantities(xc, baseline=baseline, with_ttr=with_ttr)
        return _digest(*(q[k] for k in sorted(q)))
    for baseline in (False, True):
        for with_ttr in (True, False):
            cases[f"criticality_quantities baseline={baseline} ttr={with_ttr}"] = (
                partial(crit_case, baseline, with_ttr))

    def bound_case() -> str:
        return _digest(*(a_req_bound(xc, lw, stop_at=s) for lw in (3.5, 3.0)
                         for s in (0.0, 2.0, 6.0)))
    cases["a_req_bound"] = bound_case

    def score_case() -> str:
        out = []
        for i, row in enumerate(rows[:12]):
            for kw in ({}, {"wagner_scan": True, "include_scenario": True},
                       {"score": False}, {"lane_width": 3.2, "seed": 4,
                                          "builder_kwargs": {"duration": 15.0}}):
                rec, scen = score_vector(row, index=i, **kw)
                out.append(rec.to_dict() if hasattr(rec, "to_dict") else vars(rec))
                out.append(None if scen is None else scen.to_dict())
        rec, _ = score_vector({**rows[0], "p_y1": 0.0})
        out.append(vars(rec))
        return _digest(out)
    cases["score_vector"] = score_case

    def estimator_case() -> str:
        return _digest(PRegionEstimator().settings(),
                       PRegionEstimator(3, 5, 7, 9, 11, 0.2, 1.1, 13, (2.0,), 17, 1e-9, 0.9,
                                        19, 0.3, 23, 29).settings())
    cases["PRegionEstimator settings"] = estimator_case

    def derive_case() -> str:
        q = derive(xc, QUANTITY_NAMES, model=model)
        return _digest(*(q[k] for k in QUANTITY_NAMES))
    cases["derive every quantity"] = derive_case

    def io_case() -> str:
        d = model_to_dict(model)
        out: list[Any] = [model_to_dict(model_from_dict(CutInGMM, d))]
        t_bad = [dict(t) for t in d["transforms"]]
        t_bad[1]["scale"] = 0.0
        bads = [None, {**d, "format": "x"}, {k: v for k, v in d.items() if k != "means"},
                {**d, "features": "gap"}, {**d, "settings": 3},
                {**d, "settings": {"n_init": 2, "bogus": 1}},
                {**d, "transforms": d["transforms"][:-1]}, {**d, "transforms": t_bad},
                {**d, "weights": "abc"}, {**d, "means": [[0.0]]}, {**d, "fixed": 3},
                {**d, "fixed": {}}, {**d, "lane_width": 11}, {**d, "lane_width": True},
                {**d, "exposure": 3}, {**d, "bootstrap": {"weights": 1}},
                {**d, "support": {"bogus": 1}}, {**d, "fit_report": None}]
        for bad in bads:
            try:
                out.append(model_to_dict(model_from_dict(CutInGMM, bad)))
            except Exception as exc:
                out.append(f"{type(exc).__name__}: {exc}")
        return _digest(out)
    cases["model_to_dict / model_from_dict"] = io_case

    def runner_case() -> str:
        from riskcore.sut import SimSettings, make_sut
        from sampler.campaign import sut_runner

        runner = sut_runner(lambda: make_sut("acc", k2=0.5), careful=True,
                            settings=SimSettings(t_max=40.0), lane_width=model.lane_width_)
        seeds = np.arange(xc.shape[0], dtype=np.uint64)
        out = [runner(xc[i:i + 100], seeds[i:i + 100]) for i in (0, 100, 200)]
        return _digest(*(np.asarray(o.arrays[k]) if o.arrays[k].dtype.kind != "U"
                         else o.arrays[k].tolist() for o in out for k in sorted(o.arrays)))
    cases["sut_runner acc k2=0.5, careful, t_max 40 s"] = runner_case

    def tracks_case() -> str:
        from sampler.scenario.batch import buildable_batches, cutin_tracks

        odd = np.repeat(xc[:1], 6, axis=0)  # refusals: not finite, p_t, p_a3, p_y1, dv
        odd[0, 0], odd[1, 1], odd[2, 4], odd[3, 0], odd[4, 6] = np.nan, -1, -1, 0, -80
        odd[5, 3], odd[5, 4] = 0.0, 0.0  # a pulse edge on a panel edge
        xs = np.vstack([xc, odd])
        out = []
        for quad in ("gauss", "trapezoid"):
            for kw in ({}, {"lane_width": 3.2, "lead_in": 0.0, "dt": 0.05}):
                out.append(_digest(*cutin_tracks(xs, quadrature=quad, **kw)))
        for quad in ("gauss", "trapezoid"):
            status, batches = buildable_batches(xs[:80], quadrature=quad)
            out.append(_digest(status))
            for idx, b in batches:
                out.append(_digest(idx, *(v for v in vars(b).values()
                                          if isinstance(v, np.ndarray))))
        return _digest(out)
    cases["cutin_tracks gauss/trapezoid, buildable_batches"] = tracks_case

    def score_samples_case() -> str:
        drawn = sample(model, ["ttc<3"], n=30, seed=21, method="rejection")
        out: list[Any] = []
        for src, kw in ((drawn, {"chunk_size": 7}), (drawn.params, {"score": False}),
                        (rows[:5], {"include_scenarios": True, "chunk_size": 2,
                                    "builder_kwargs": {"duration": 12.0}})):
            got: list[tuple[int, int]] = []
            recs = score_samples(src, progress=partial(_note, got), **kw)
            out.append([vars(r) for r in recs])
            out.append(got)
        return _digest(out)
    cases["score_samples"] = score_samples_case

    def subset_is_case() -> str:
        s = sample(model, ["ttc<1.5"], 100, seed=4, method="subset-is")
        return _digest(np.asarray(s.params), s.log_density, s.exposure_weights,
                       _no_clock(s.diagnostics), _no_clock(s.p_region.to_dict()))
    cases["sample subset-is ttc<1.5"] = subset_is_case

    def stratified_case() -> str:
        out = []
        runs: list[tuple[list[str], dict[str, Any]]] = [
            (["ttc<2"], {"stratify": "always"}), (["ttc<1.5", "gap<15"], {})]
        for cons, kw in runs:
            r = rare_probability(model, cons, 5, **kw)
            out.append(_digest(r.z, r.log_w, _no_clock(r.summary()), r.method))
        return _digest(out)
    cases["rare_probability stratified ttc<2, auto ttc<1.5 & gap<15"] = stratified_case
    return cases


def main() -> None:
    mode, path = sys.argv[1], sys.argv[2]
    model = CutInGMM(k_range=(1, 6), n_report_samples=500).fit(default_parameter_table())
    got = {}
    for name, case in _cases(model).items():
        try:
            got[name] = case()
        except Exception as exc:
            got[name] = f"error {type(exc).__name__}: {exc}"
        print(f"{got[name][:16]}  {name}")
    if mode == "record":
        with open(path, "w") as f:
            json.dump(got, f, indent=1)
        return
    with open(path) as f:
        before = json.load(f)
    changed = [k for k in sorted(set(before) | set(got)) if before.get(k) != got.get(k)]
    for k in changed:
        print(f"CHANGED {k}: {before.get(k)} -> {got.get(k)}")
    print("identical" if not changed else f"{len(changed)} changed")
    sys.exit(1 if changed else 0)


if __name__ == "__main__":
    main()
