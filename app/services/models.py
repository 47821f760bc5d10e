"""Fitted cut-in models: the one way a model is fitted, fitting on a stored dataset, lookups.

``fit_model`` is the only fit path: ``POST /models``, ``scengen fit`` and the default model
of the embedded data all call it. Its order, and why:

1. check the options (``n_bootstrap``, the ``CutInGMM`` keywords) and the exposure: cheap,
   so a bad request fails before seconds of EM;
2. fit the mixture (K by BIC) on the table;
3. the bootstrap refits of the model interval (``n_bootstrap``, default
   ``DEFAULT_BOOTSTRAP`` = 100; 0: none), seeded with the model's ``random_state``;
4. attach the exposure: the one given (an upload's or the command line's), else the embedded
   TNO data's 63 hours when every row is from it, else none.

The exposure enters neither the fit nor the refits, so steps 3 and 4 commute; the CLI used
to attach it before the refits and the service after, with the same result (the model's
JSON is the same bytes). ``bootstrap_jobs`` only spreads the refits over processes: the
replicates do not depend on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from app import budget, domain, jsonconv
from app.context import ServiceContext
from app.db import repository as repo
from app.db.models import ModelRow
from app.errors import InvalidInput
from app.limits import check_model_options
from datasets import EMBEDDED_SOURCE
from riskcore import FieldError
from sampler import CutInGMM, SamplerError
from sampler.model import bootstrap_fit
from sampler.rates import Exposure, tno_exposure

__all__ = ["DEFAULT_BOOTSTRAP", "fit_model", "fit_on_dataset", "list_models", "model_and_row",
           "model_row"]

#: bootstrap refits stored with a model when its options do not say (issue 12)
DEFAULT_BOOTSTRAP = 100


def _n_bootstrap(options: dict[str, Any]) -> int:
    n_boot = options.pop("n_bootstrap", DEFAULT_BOOTSTRAP)
    if isinstance(n_boot, bool) or not isinstance(n_boot, int) or n_boot == 1 or n_boot < 0:
        raise InvalidInput(f"n_bootstrap: expected 0 or 2 ... 10000 refits, got {n_boot!r}",
                           field="body.options.n_bootstrap")
    return n_boot


def _exposure(table: pd.DataFrame, given: Exposure | Mapping[str, Any] | None
              ) -> Exposure | None:
    if isinstance(given, Exposure):
        return given
    if given is not None:
        return Exposure.from_dict({**given, "n_events": len(table)})
    if "source" in table.columns and (table["source"] == EMBEDDED_SOURCE).all():
        return tno_exposure(len(table))  # 63 h (de Gelder et al. 2021)
    return None


def fit_model(table: pd.DataFrame, options: Mapping[str, Any], *, source: str | None = None,
              exposure: Exposure | Mapping[str, Any] | None = None,
              bootstrap_jobs: int = 1) -> domain.FittedModel:
    """Fit the cut-in GMM on a parameter table (the module docstring gives the order).

    ``options``: keyword options of ``CutInGMM`` plus ``n_bootstrap``; ``exposure``: the
    driving the table's cut-ins come from (an ``Exposure`` or its dict; ``n_events`` is
    the table's length); ``bootstrap_jobs``: processes for the refits (0: one per core).
    """
    kwargs = dict(options)
    n_boot = _n_bootstrap(kwargs)
    if isinstance(kwargs.get("k_range"), list):
        kwargs["k_range"] = tuple(kwargs["k_range"])
    try:
        model = CutInGMM(**kwargs)
    except (TypeError, SamplerError) as exc:
        raise InvalidInput(f"model options: {exc}", field="body.options") from None
    exp = _exposure(table, exposure)
    try:
        model.fit(table, source=source)
        if n_boot:
            bootstrap_fit(model, table, n_boot, seed=int(model.random_state),
                          n_jobs=bootstrap_jobs)
    except FieldError as exc:  # the table or options; a library's ValueError is a 500
        raise InvalidInput(f"fitting the model failed: {exc}", field="body.options") from None
    if exp is not None:
        model.exposure_ = exp.to_dict()
    return domain.describe(model)


def model_row(model_id: str, dataset_id: str, fitted: domain.FittedModel,
              options: Mapping[str, Any], is_default: bool = False) -> ModelRow:
    """The stored form of a fitted model."""
    return ModelRow(id=model_id, dataset_id=dataset_id, is_default=is_default,
                    options=jsonconv.encode(dict(options)), n_components=fitted.n_components,
                    model_hash=fitted.model_hash, model_json=fitted.model_json,
                    bic_curve=fitted.bic_curve, fit_report=fitted.fit_report)


def fit_on_dataset(ctx: ServiceContext, dataset_id: str,
                   options: Mapping[str, Any]) -> tuple[ModelRow, CutInGMM]:
    """Fit a model on a stored dataset (its table and, for highD uploads, its exposure) and
    store it under a new id. The options are checked against the service's limits."""
    check_model_options(options, ctx.settings)
    with ctx.db.session() as s:
        dataset = repo.get_dataset(s, dataset_id, field="body.dataset")
    try:
        table = ctx.dataset_table(dataset)
    except OSError as exc:
        raise InvalidInput(f"dataset {dataset_id!r} has no readable table: {exc}",
                           field="body.dataset") from None
    exposure = (dataset.report or {}).get("exposure")  # highD uploads: vehicle-h, vehicle-km
    fitted = fit_model(table, options, source=dataset.id,
                       exposure=jsonconv.decode(exposure) if exposure else None)
    row = model_row(repo.new_id("mdl"), dataset.id, fitted, options)
    budget.check_client()  # a client that gave up stores nothing
    with ctx.db.session() as s:
        s.add(row)
    return row, fitted.model


def list_models(ctx: ServiceContext) -> list[ModelRow]:
    """The stored models, the default model first."""
    with ctx.db.read_session() as s:
        return list(repo.list_models(s))


def model_and_row(ctx: ServiceContext, model_id: str,
                  field: str = "path.model_id") -> tuple[str, CutInGMM, ModelRow]:
    """A model id ('default' too) resolved: the id, the fitted model and its stored row
    (detached from the session)."""
    mid = ctx.resolve_model_id(model_id)
    model = ctx.model(mid, field=field)
    with ctx.db.read_session() as s:
        row = repo.get_model(s, mid)
        s.expunge(row)
    return mid, model, row
