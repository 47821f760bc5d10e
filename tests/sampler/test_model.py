"""The GMM scenario model: transforms, densities, BIC, JSON persistence, report."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import logsumexp

from datasets.cutin_model import PARAM_NAMES
from sampler import ModelError, NotFittedError
from sampler.model.gmm import CutInGMM
from sampler.model.transforms import FeatureTransform, transform_spec
from tests.sampler.factories import synthetic_parameter_table


@pytest.fixture(scope="module")
def fitted() -> CutInGMM:
    return CutInGMM(k_range=(1, 4), n_init=2, n_report_samples=4000).fit(
        synthetic_parameter_table(300, seed=0), source="synthetic")


# ---------------------------------------------------------------- transforms


@pytest.mark.parametrize("kind,shift", [("identity", 0.0), ("log", 0.0), ("log_shift", 0.1)])
def test_transform_inverse_and_jacobian(kind: str, shift: float) -> None:
    tr = FeatureTransform("f", kind, shift, loc=0.3, scale=1.7)
    x = np.array([0.0 if kind != "log" else 0.5, 0.25, 1.0, 7.5])
    z, logj = tr.forward(x)
    np.testing.assert_allclose(tr.inverse(z), x, rtol=1e-12, atol=1e-12)
    # numerical derivative dz/dx against the analytic log-Jacobian
    h = 1e-6
    num = (tr.forward(x + h)[0] - tr.forward(x - h)[0]) / (2 * h)
    np.testing.assert_allclose(logj, np.log(num), rtol=1e-6)


def test_transform_by_hand_and_domain() -> None:
    tr = FeatureTransform("gap", "log", 0.0, loc=math.log(10.0), scale=2.0)
    z, logj = tr.forward(np.array([10.0, -1.0]))
    assert z[0] == 0.0 and logj[0] == pytest.approx(-math.log(10.0) - math.log(2.0))
    assert np.isnan(z[1]) and logj[1] == -np.inf
    with pytest.raises(ModelError, match="valid: identity, log, log_shift"):
        transform_spec("gap", "sqrt")
    with pytest.raises(ModelError, match="shift > 0"):
        transform_spec("p_a3", ("log_shift", 0.0))
    assert transform_spec("p_a3", "log_shift") == ("log_shift", 0.1)
    assert transform_spec("p_t") == ("log", 0.0) and transform_spec("dv") == ("identity", 0.0)


# ---------------------------------------------------------------- densities


def _reference_log_density(model: CutInGMM, x: np.ndarray) -> np.ndarray:
    """Slow, independent: scipy's multivariate normal per row and component + Jacobian."""
    out = np.empty(x.shape[0])
    for i, row in enumerate(x):
        z = np.empty_like(row)
        logj = 0.0
        for j, tr in enumerate(model.transforms_):
            if tr.kind == "identity":
                y, dy = row[j], 1.0
            elif tr.kind == "log":
                y, dy = math.log(row[j]), 1.0 / row[j]
            else:
                y, dy = math.log(row[j] + tr.shift), 1.0 / (row[j] + tr.shift)
            z[j] = (y - tr.loc) / tr.scale
            logj += math.log(dy / tr.scale)
        comps = [math.log(w) + stats.multivariate_normal(m, c).logpdf(z)
                 for w, m, c in zip(model.weights_, model.means_, model.covariances_,
                                    strict=True)]
        out[i] = logsumexp(comps) + logj
    return out


def test_log_density_matches_slow_reference(fitted: CutInGMM) -> None:
    x = fitted.sample(40, np.random.default_rng(5))
    x = x[(x[:, PARAM_NAMES.index("p_a3")] > -0.1 + 1e-9)]
    np.testing.assert_allclose(fitted.log_density(x), _reference_log_density(fitted, x),
                               rtol=1e-10, atol=1e-9)


def test_log_density_matches_sklearn_in_z_space() -> None:
    from sklearn.mixture import GaussianMixture

    table = synthetic_parameter_table(200, seed=4)
    model = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=500).fit(table)
    z = model.to_z(table[list(PARAM_NAMES)].to_numpy())
    gm = GaussianMixture(2, n_init=1, reg_covar=1e-4, max_iter=500, random_state=0).fit(z)
    np.testing.assert_allclose(model.log_density_z(z), gm.score_samples(z), rtol=1e-9)


def test_one_dimensional_density_integrates_to_one() -> None:
    table = synthetic_parameter_table(300, seed=2)
    model = CutInGMM(features=["gap"], k_range=(1, 3), n_init=1,
                     n_report_samples=500).fit(table)
    grid = np.linspace(1e-3, 400.0, 400_001)
    dens = np.exp(model.log_density(grid[:, None]))
    assert np.trapezoid(dens, grid) == pytest.approx(1.0, abs=2e-3)
    # the other parameters are held at the table's medians
    assert model.fixed_["dv"] == pytest.approx(float(np.median(table["dv"])))
    assert model.params_matrix(np.array([[5.0]]))[0, PARAM_NAMES.index("gap")] == 5.0


def test_outside_domain_is_minus_inf(fitted: CutInGMM) -> None:
    x = fitted.sample(3, np.random.default_rng(0))
    x[0, PARAM_NAMES.index("gap")] = -1.0
    x[1, PARAM_NAMES.index("p_t")] = np.nan
    ld = fitted.log_density(x)
    assert ld[0] == -np.inf and ld[1] == -np.inf and np.isfinite(ld[2])


# ---------------------------------------------------------------- sampling


def test_sample_is_not_grouped_and_advances_the_generator(fitted: CutInGMM) -> None:
    rng = np.random.default_rng(11)
    a = fitted.sample(500, rng)
    b = fitted.sample(500, rng)
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(a, fitted.sample(500, np.random.default_rng(11)))
    # not sorted by component: labels change often along the sample order
    z = fitted.to_z(a)
    dens = np.stack([stats.multivariate_normal(m, c).logpdf(z)
                     for m, c in zip(fitted.means_, fitted.covariances_, strict=True)])
    labels = dens.argmax(axis=0)
    assert np.count_nonzero(np.diff(labels)) > 100


def test_sample_moments_match_mixture(fitted: CutInGMM) -> None:
    z = fitted.sample_z(100_000, np.random.default_rng(3))
    mean = fitted.weights_ @ fitted.means_
    se = z.std(axis=0) / math.sqrt(z.shape[0])
    assert (np.abs(z.mean(axis=0) - mean) < 5 * se).all()


def test_sample_needs_generator(fitted: CutInGMM) -> None:
    with pytest.raises(TypeError, match="Generator"):
        fitted.sample(3, 0)  # type: ignore[arg-type]


# ---------------------------------------------------------------- BIC and report


def test_bic_recovers_number_of_clusters() -> None:
    rng = np.random.default_rng(0)
    n = 400
    centres = np.array([[-3.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    lab = rng.integers(0, 3, n)
    xy = centres[lab] + rng.standard_normal((n, 2)) * 0.5
    table = pd.DataFrame({"dv": xy[:, 0], "p_a1": xy[:, 1]})
    fixed = {k: 1.0 for k in PARAM_NAMES if k not in ("dv", "p_a1")}
    model = CutInGMM(features=["dv", "p_a1"], k_range=(1, 5), n_init=2, fixed=fixed,
                     n_report_samples=500).fit(table)
    assert model.n_components_ == 3
    curve = [c["bic"] for c in model.bic_curve_]
    assert len(curve) == 5 and int(np.argmin(curve)) == 2
    # BIC by hand from the stored log-likelihood: n_par = 2 + 6 + 9 for K=3, d=2
    c3 = model.bic_curve_[2]
    assert c3["n_parameters"] == 17
    assert c3["bic"] == pytest.approx(-2 * c3["log_likelihood"] + 17 * math.log(n))


def test_fit_report_contents(fitted: CutInGMM) -> None:
    r = fitted.fit_report_
    assert r["k"] == fitted.n_components_ and r["n_rows"] == 300
    h = r["heldout_loglik_per_row"]
    assert h["folds"] == 5 and len(h["per_fold"]) == 5
    # held-out likelihood is below the in-sample one but not absurdly
    assert h["mean"] < r["loglik_per_row"] < h["mean"] + 5
    assert set(r["ks"]) == set(PARAM_NAMES)
    assert all(0 <= v["statistic"] <= 1 for v in r["ks"].values())
    ob = r["outside_bounds"]
    assert 0 <= ob["ci95"][0] <= ob["fraction"] <= ob["ci95"][1] <= 1
    assert "p_a3>=0" in ob["per_bound"]
    text = fitted.report_text()
    assert "<- chosen" in text and "held-out" in text and "KS statistic" in text


def test_report_ks_detects_a_wrong_model() -> None:
    table = synthetic_parameter_table(300, seed=0)
    good = CutInGMM(k_range=(2, 2), n_init=1, n_report_samples=4000).fit(table)
    # a shifted copy of the data: the model of the original is far from it
    wrong = table.copy()
    wrong["gap"] = wrong["gap"] * 3
    ks_wrong = stats.ks_2samp(wrong["gap"], good.sample(4000, np.random.default_rng(0))[
        :, PARAM_NAMES.index("gap")]).statistic
    assert good.fit_report_["ks"]["gap"]["statistic"] < 0.1 < ks_wrong


# ---------------------------------------------------------------- persistence


def test_json_round_trip_is_exact(fitted: CutInGMM, tmp_path: object) -> None:
    text = fitted.to_json()
    data = json.loads(text)
    for key in ("weights", "means", "covariances", "transforms", "features", "training",
                "sklearn_version", "bic_curve", "fit_report"):
        assert key in data
    assert len(data["training"]["sha256"]) == 64
    back = CutInGMM.from_json(text)
    x = fitted.sample(300, np.random.default_rng(9))
    np.testing.assert_allclose(back.log_density(x), fitted.log_density(x), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.sample(50, np.random.default_rng(1)),
                                  fitted.sample(50, np.random.default_rng(1)))
    assert back.to_json() == text
    path = tmp_path / "m.json"  # type: ignore[operator]
    fitted.save(path)
    assert CutInGMM.load(path).to_json() == text


def test_training_hash_tracks_the_data() -> None:
    t1 = synthetic_parameter_table(100, seed=1)
    t2 = t1.copy()
    t2.loc[3, "gap"] += 1e-9
    kw = dict(k_range=(1, 1), n_init=1, n_report_samples=200)
    h1 = CutInGMM(**kw).fit(t1).training_["sha256"]  # type: ignore[arg-type]
    assert h1 == CutInGMM(**kw).fit(t1.copy()).training_["sha256"]  # type: ignore[arg-type]
    assert h1 != CutInGMM(**kw).fit(t2).training_["sha256"]  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [(lambda d: d.pop("weights"), "weights: missing"),
     (lambda d: d.update(format="x"), "format"),
     (lambda d: d.update(weights=[0.5] * len(d["weights"])), "sum to 1"),
     (lambda d: d["covariances"][0][0].__setitem__(0, -5.0), "positive definite|symmetric"),
     (lambda d: d["transforms"][0].update(kind="cube"), "unknown kind"),
     (lambda d: d["transforms"][1].update(scale=0), "scale > 0"),
     (lambda d: d.update(features=["a"]), "one entry per feature")],
)
def test_bad_model_json(fitted: CutInGMM, mutate: object, fragment: str) -> None:
    data = json.loads(fitted.to_json())
    mutate(data)  # type: ignore[operator]
    with pytest.raises(ModelError, match=fragment):
        CutInGMM.from_dict(data)


def test_load_errors(tmp_path: object) -> None:
    with pytest.raises(ModelError, match="cannot read"):
        CutInGMM.load(tmp_path / "missing.json")  # type: ignore[operator]
    bad = tmp_path / "bad.json"  # type: ignore[operator]
    bad.write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        CutInGMM.load(bad)


# ---------------------------------------------------------------- bad tables


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [(lambda t: t.drop(columns="gap"), "missing column"),
     (lambda t: t.assign(gap=t["gap"].where(t.index != 7, np.nan)), "'gap' row 7"),
     (lambda t: t.assign(p_t=t["p_t"].where(t.index != 2, -1.0)), "'p_t' row 2.*log"),
     (lambda t: t.assign(dv="x"), "not numeric"),
     (lambda t: t.head(5), "too few"),
     (lambda t: t.assign(p_a1=0.0), "constant")],
)
def test_bad_tables(mutate: object, fragment: str) -> None:
    table = mutate(synthetic_parameter_table(60, seed=0))  # type: ignore[operator]
    with pytest.raises(ModelError, match=fragment):
        CutInGMM(k_range=(1, 2), n_init=1).fit(table)


def test_not_fitted_and_bad_settings() -> None:
    with pytest.raises(NotFittedError, match="not fitted"):
        CutInGMM().log_density(np.zeros((1, 8)))
    with pytest.raises(ModelError, match="k_range"):
        CutInGMM(k_range=(3, 1)).fit(synthetic_parameter_table(50))
    with pytest.raises(ModelError, match="covariance_type"):
        CutInGMM(covariance_type="banana").fit(synthetic_parameter_table(50))
    with pytest.raises(ModelError, match="transforms: not model features"):
        CutInGMM(transforms={"ttc": "log"}).fit(synthetic_parameter_table(50))


@settings(max_examples=60, deadline=None)
@given(kind=st.sampled_from(["identity", "log", "log_shift"]),
       x=st.floats(1e-3, 1e3), loc=st.floats(-5, 5), scale=st.floats(0.05, 20),
       shift=st.floats(0.01, 2.0))
def test_property_transform_round_trip_and_monotone(kind: str, x: float, loc: float,
                                                    scale: float, shift: float) -> None:
    tr = FeatureTransform("f", kind, shift if kind == "log_shift" else 0.0, loc, scale)
    xs = np.array([x, x * 1.01 + 1e-3])
    z, logj = tr.forward(xs)
    assert np.isfinite(z).all() and np.isfinite(logj).all()
    assert z[1] > z[0]  # increasing: constraints on x are half-spaces in z
    np.testing.assert_allclose(tr.inverse(z), xs, rtol=1e-9, atol=1e-9)
