"""One fit path: ``scengen fit``, ``POST /models`` and the default model all go through
``app.services.models.fit_model``; its checks come before the fit."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from app.cli import main
from app.errors import InvalidInput
from app.services.models import DEFAULT_BOOTSTRAP, fit_model
from sampler import CutInGMM, ModelError
from sampler.rates import Exposure
from tests.sampler.factories import synthetic_parameter_table

QUICK = {"k_range": (1, 2), "n_init": 1, "cv_folds": 2, "n_report_samples": 500}


@pytest.mark.slow
def test_the_cli_writes_the_model_the_service_fits(tmp_path: Path) -> None:
    table_path = tmp_path / "table.csv"
    synthetic_parameter_table(120, seed=3).to_csv(table_path, index=False)
    out = tmp_path / "cli.json"
    assert main(["fit", str(table_path), "-o", str(out), "--k-min", "1", "--k-max", "2",
                 "--n-init", "1", "--seed", "4", "--bootstrap", "3",
                 "--exposure-hours", "12.5"]) == 0
    table = pd.read_csv(table_path)
    exposure = Exposure(n_events=len(table), hours=12.5, km=None,
                        source="given on the command line")
    fitted = fit_model(table, {"k_range": (1, 2), "n_init": 1, "random_state": 4,
                               "n_bootstrap": 3}, source=str(table_path), exposure=exposure)
    # the same model: every number of the file equal (JSON floats round-trip exactly)
    assert json.loads(out.read_text(encoding="utf-8")) == json.loads(fitted.model_json)
    model = CutInGMM.load(out)
    assert model.bootstrap_ is not None and model.bootstrap_["n_boot"] == 3
    assert model.exposure_ == exposure.to_dict()


def test_options_and_exposure_are_checked_before_the_fit(monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    def no_fit(*args: object, **kwargs: object) -> None:
        raise AssertionError("the model was fitted before its inputs were checked")

    monkeypatch.setattr(CutInGMM, "fit", no_fit)
    table = synthetic_parameter_table(50, seed=1)
    with pytest.raises(ModelError, match="exposure"):
        fit_model(table, QUICK, exposure={"hours": "many"})
    with pytest.raises(InvalidInput) as info:
        fit_model(table, {**QUICK, "n_bootstrap": 1})
    assert info.value.field == "body.options.n_bootstrap"
    with pytest.raises(InvalidInput) as info:
        fit_model(table, {**QUICK, "no_such_option": 1})
    assert info.value.field == "body.options"


def test_default_refits_and_the_embedded_exposure() -> None:
    from datasets import default_parameter_table

    table = default_parameter_table()
    fitted = fit_model(table, QUICK)
    assert fitted.model.bootstrap_ is not None
    assert fitted.model.bootstrap_["n_boot"] == DEFAULT_BOOTSTRAP == 100
    exposure = fitted.model.exposure_
    assert exposure is not None and exposure["hours"] == 63.0
    assert exposure["n_events"] == len(table)
