"""Model uncertainty (bootstrap refits), exposure and rates."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from app.cli import main
from sampler import ModelError
from sampler.bootstrap import bootstrap_fit, model_interval
from sampler.constraints import Region
from sampler.exposure import (
    Exposure,
    cutin_rate,
    highd_exposure,
    region_rates,
    region_report,
    tno_exposure,
)
from sampler.model import CutInGMM
from sampler.sampleset import sample
from tests.sampler.factories import base_params, synthetic_parameter_table

# the known mixture of (gap, dv) the coverage test draws its data sets from
TRUE_W = np.array([0.6, 0.4])
TRUE_MU = np.array([[30.0, -1.0], [16.0, 2.0]])
TRUE_SD = np.array([[6.0, 1.5], [4.0, 1.0]])
CUT = 9.0  # region gap < 9 m


def _true_p() -> float:
    return float(sum(w * stats.norm.cdf((CUT - m[0]) / s[0])
                     for w, m, s in zip(TRUE_W, TRUE_MU, TRUE_SD, strict=True)))


def _draw_table(n: int, rng: np.random.Generator) -> pd.DataFrame:
    lab = rng.random(n) < TRUE_W[1]
    mu, sd = TRUE_MU[lab.astype(int)], TRUE_SD[lab.astype(int)]
    x = mu + sd * rng.standard_normal((n, 2))
    return pd.DataFrame({"gap": x[:, 0], "dv": x[:, 1]})


def test_bootstrap_interval_covers_the_true_probability() -> None:
    """Data sets of 250 rows from a known 2-component GMM; P(gap < 9) under it is known in
    closed form (~1.2 %, in the tail of one component); the model interval (60 refits,
    95 %) must cover it in most repetitions."""
    p_true = _true_p()
    assert 0.005 < p_true < 0.03
    fixed = {k: v for k, v in base_params().items() if k not in ("gap", "dv")}
    covered, width = [], []
    for rep in range(25):
        rng = np.random.default_rng(1000 + rep)
        table = _draw_table(250, rng)
        model = CutInGMM(features=["gap", "dv"], transforms={"gap": "identity"},
                         k_range=(2, 2), n_init=2, n_report_samples=200, cv_folds=2,
                         fixed=fixed).fit(table)
        bootstrap_fit(model, table, 60, seed=rep)
        z = model.sample_z(40_000, rng)
        inside = model.from_z(z)[:, 0] < CUT
        p_joint = float(inside.mean())
        iv = model_interval(model, z[inside], p_joint, z[:4096], np.ones(4096, dtype=bool))
        lo, hi = iv["ci"]
        covered.append(lo <= p_true <= hi)
        width.append(hi / lo)
    # nominal 95 %; percentile bootstrap intervals of tail probabilities from 250 rows
    # undercover a little, so the bar is 80 % (measured: see the commit)
    assert np.mean(covered) >= 0.8
    assert np.median(width) > 1.2  # a real interval, not a point


def test_bootstrap_is_deterministic_and_independent_of_jobs() -> None:
    table = synthetic_parameter_table(300, seed=0)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)
    a = bootstrap_fit(model, table, 6, seed=3, n_jobs=1)
    b = bootstrap_fit(model, table, 6, seed=3, n_jobs=2)
    assert json.dumps(a) == json.dumps(b)
    assert bootstrap_fit(model, table, 6, seed=4)["means"] != a["means"]


def test_bootstrap_and_exposure_survive_json(tmp_path: Path) -> None:
    table = synthetic_parameter_table(300, seed=0)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)
    bootstrap_fit(model, table, 4, seed=0)
    model.exposure_ = Exposure(n_events=300, hours=10.0, km=900.0, source="test").to_dict()
    model.save(tmp_path / "m.json")
    back = CutInGMM.load(tmp_path / "m.json")
    assert back.bootstrap_ == json.loads(json.dumps(model.bootstrap_))
    assert back.exposure_ == model.exposure_
    data = json.loads((tmp_path / "m.json").read_text())
    data["bootstrap"]["means"] = [*data["bootstrap"]["means"][:1], [[0.0]]]
    with pytest.raises(ModelError, match="bootstrap"):
        CutInGMM.from_dict(data)
    data["bootstrap"] = "many"
    with pytest.raises(ModelError, match="bootstrap: expected an object"):
        CutInGMM.from_dict(data)


def test_rates_hand_computed() -> None:
    exp = Exposure(n_events=208, hours=63.0, km=None, source="test")
    lam = 208 / 63.0
    r = region_rates(exp, {"estimate": 1e-3, "ci_low": 9e-4, "ci_high": 1.2e-3})
    assert r["per_hour"]["estimate"] == pytest.approx(lam * 1e-3, rel=1e-12)
    assert r["per_hour"]["mc_ci"] == pytest.approx([lam * 9e-4, lam * 1.2e-3], rel=1e-12)
    assert r["per_hour"]["model_ci"] is None
    assert "per_1e6_km" not in r
    # the count's exact Poisson interval: gamma quantiles (Garwood), 208 events
    ci = cutin_rate(exp)["per_hour"]["ci"]
    assert ci[0] * 63 == pytest.approx(stats.gamma.ppf(0.025, 208), rel=1e-9)
    assert ci[1] * 63 == pytest.approx(stats.gamma.ppf(0.975, 209), rel=1e-9)
    # model interval: replicates of P(A) times Poisson counts
    r2 = region_rates(exp, {"estimate": 1e-3, "ci_low": 9e-4, "ci_high": 1.2e-3},
                      {"replicates": [1e-3] * 400}, seed=1)
    lo, hi = r2["per_hour"]["model_ci"]
    assert lo < lam * 1e-3 < hi
    assert hi / lo == pytest.approx(238.0 / 180.0, rel=0.1)  # the count's spread only
    km = region_rates(Exposure(n_events=50, hours=None, km=2000.0, source="t"),
                      {"estimate": 0.01, "ci_low": 0.005, "ci_high": 0.02})
    assert km["per_1e6_km"]["estimate"] == pytest.approx(50 / 2000.0 * 1e6 * 0.01)


def test_exposure_validation_and_sources() -> None:
    with pytest.raises(ModelError, match="hours, km or both"):
        Exposure(n_events=3, hours=None, km=None, source="x")
    with pytest.raises(ModelError, match=r"exposure\.hours"):
        Exposure(n_events=3, hours=-1.0, km=None, source="x")
    assert tno_exposure(208).hours == 63.0 and tno_exposure(208).km is None
    metas = [pd.DataFrame({"totalDrivenTime": [7200.0], "totalDrivenDistance": [150_000.0]}),
             pd.DataFrame({"totalDrivenTime": [3600.0], "totalDrivenDistance": [90_000.0]})]
    e = highd_exposure(metas, n_events=12)
    assert e.hours == pytest.approx(3.0) and e.km == pytest.approx(240.0)


def test_region_report_weights_sum_to_the_rate() -> None:
    table = synthetic_parameter_table(300, seed=0)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)
    bootstrap_fit(model, table, 20, seed=0)
    model.exposure_ = Exposure(n_events=300, hours=25.0, km=2500.0, source="t").to_dict()
    ss = sample(model, ["ttc<8"], 200, seed=1)
    rep = region_report(model, ss, seed=1)
    lam_h = 300 / 25.0
    assert rep["rates"]["per_hour"]["estimate"] == pytest.approx(lam_h * ss.p_region.estimate)
    assert float(ss.exposure_weights.sum()) * lam_h == pytest.approx(
        rep["rates"]["per_hour"]["estimate"])
    assert rep["rates"]["per_hour"]["weight_per_sample"] * 200 == pytest.approx(
        rep["rates"]["per_hour"]["estimate"])
    lo, hi = rep["p_region"]["model_ci"]
    assert lo < hi and lo > 0
    assert rep["rates"]["per_1e6_km"]["model_ci"][0] > 0
    assert region_report(model, ss, seed=1) == rep  # deterministic


def test_cli_fit_stores_bootstrap_and_tno_exposure(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "tno.json"
    assert main(["fit", "-o", str(out), "--k-max", "3", "--n-init", "1",
                 "--bootstrap", "5"]) == 0
    text = capsys.readouterr().out
    assert "cut-ins per hour" in text and "63 hours" in text
    data = json.loads(out.read_text())
    assert data["exposure"]["hours"] == 63.0 and data["bootstrap"]["n_boot"] == 5
    assert main(["sample", str(out), "-c", "ttc<3", "-n", "50", "--seed", "1", "-q",
                 "-o", str(tmp_path / "s.jsonl")]) == 0
    err = capsys.readouterr().err
    assert "rate per hour" in err and "model [" in err
    assert main(["fit", "-o", str(out), "--bootstrap", "1"]) == 2
    assert math.isfinite(Region().lane_width)


def test_tail_calibration_in_the_fit_report() -> None:
    table = synthetic_parameter_table(400, seed=2)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=4000).fit(table)
    tc = model.fit_report_["tail_calibration"]
    names = {r["quantity"] for r in tc["rows"]}
    assert {"ttc", "thw", "gap"} <= names
    for r in tc["rows"]:
        # the folds partition the rows: the pooled held-out share is the data's share
        assert r["heldout_share"] == pytest.approx(r["data_share"], abs=1e-12)
        assert 0.0 <= r["model_p"] <= 1.0
        assert r["heldout_ci95"][0] <= r["heldout_share"] <= r["heldout_ci95"][1]
    # gap is modelled directly (log-normal data, log transform): calibrated in its tail
    gap_rows = [r for r in tc["rows"] if r["quantity"] == "gap"]
    assert sum(r["inside_ci"] for r in gap_rows) >= len(gap_rows) - 1
    assert "tail calibration" in model.report_text()
