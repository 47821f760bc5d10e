"""A campaign's defaults are one value everywhere a campaign can start without them:
``sampler.campaign.evaluate()``, ``CampaignResult``, ``POST /evaluations`` (its request
model and its OpenAPI schema), the service's use cases and ``scengen evaluate`` (what it
runs with and what its --help says). The stop rule's relative half-width is defined in
the sampler (``DEFAULT_RHW``); the adaptation's default is ``evaluate()``'s ``adapt``.
``scengen evaluate`` writes both out (``app.cli.evaluate.DEFAULT_RHW``, ``ADAPT_CHOICES``)
so that its parser and --help import no sampler; these tests are what keeps the copies
equal. Each default is read from the place itself, never from the constant, so a default
written out differently anywhere fails here."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import typing
from pathlib import Path
from typing import Any

import pytest

from sampler.campaign import DEFAULT_RHW, CampaignResult, evaluate
from tests.app.factories import make_app, make_settings


class _Captured(Exception):
    """Stops ``scengen evaluate`` where it would start the campaign."""


def _cli_spec(monkeypatch: pytest.MonkeyPatch, argv: list[str]) -> Any:
    """The ``CampaignSpec`` ``scengen evaluate`` hands its campaign (which is not run)."""
    import app.cli.sampling
    from app.cli import build_parser
    from app.services import evaluations as service

    seen: list[service.CampaignSpec] = []

    def campaign(model: Any, factory: Any, spec: service.CampaignSpec,
                 **_: Any) -> None:
        seen.append(spec)
        raise _Captured

    monkeypatch.setattr(service, "campaign", campaign)
    monkeypatch.setattr(app.cli.sampling, "_load_model", lambda ref: None)
    args = build_parser().parse_args(["evaluate", "-q", "--sut", "acc", *argv])
    with pytest.raises(_Captured):
        args.func(args)
    [spec] = seen
    return spec


def _evaluate_parser() -> argparse.ArgumentParser:
    from app.cli import build_parser

    parser = build_parser()
    [sub] = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    evaluate_parser: argparse.ArgumentParser = sub.choices["evaluate"]
    return evaluate_parser


def _evaluate_help() -> str:
    return " ".join(_evaluate_parser().format_help().split())


def _openapi_request(tmp_path: Path) -> dict[str, Any]:
    openapi = make_app(make_settings(tmp_path)).openapi()
    request: dict[str, Any] = openapi["components"]["schemas"]["EvaluationRequest"]
    return request


def test_every_default_rhw_is_the_samplers(monkeypatch: pytest.MonkeyPatch,
                                           tmp_path: Path) -> None:
    import app.cli.evaluate as cli
    from app.routes.evaluations import EvaluationRequest
    from app.services import evaluations as service

    defaults = {
        "evaluate()": inspect.signature(evaluate).parameters["rhw"].default,
        "CampaignResult.rhw_target": {f.name: f.default for f in
                                      dataclasses.fields(CampaignResult)}["rhw_target"],
        "EvaluationRequest.rhw": EvaluationRequest(sut="acc").rhw,
        "OpenAPI EvaluationRequest.rhw":
            _openapi_request(tmp_path)["properties"]["rhw"]["default"],
        "app.services.evaluations.DEFAULT_RHW": service.DEFAULT_RHW,
        "evaluations.create()": inspect.signature(service.create).parameters["rhw"].default,
        "evaluations.validate()":
            inspect.signature(service.validate).parameters["rhw"].default,
        "app.cli.evaluate.DEFAULT_RHW": cli.DEFAULT_RHW,
        "scengen evaluate": _cli_spec(monkeypatch, []).rhw,
    }
    assert {k: v for k, v in defaults.items() if v != DEFAULT_RHW} == {}
    assert f"with at least 10 collisions (default {DEFAULT_RHW})" in _evaluate_help()


def test_every_default_adapt_is_the_samplers(monkeypatch: pytest.MonkeyPatch,
                                             tmp_path: Path) -> None:
    import app.cli.evaluate as cli
    from app.routes.evaluations import EvaluationRequest
    from app.services import evaluations as service

    default = inspect.signature(evaluate).parameters["adapt"].default
    assert default == "ce"  # docs/api.md and docs/evaluation.md: "ce" (default)
    [cli_adapt] = [a for a in _evaluate_parser()._actions if a.dest == "adapt"]
    defaults = {
        "evaluations.create()":
            inspect.signature(service.create).parameters["adapt"].default,
        "evaluations.validate()":
            inspect.signature(service.validate).parameters["adapt"].default,
        "CampaignSpec.adapt": {f.name: f.default for f in
                               dataclasses.fields(service.CampaignSpec)}["adapt"],
        "app.services.evaluations.ADAPT[0] (default first)": service.ADAPT[0],
        "EvaluationRequest.adapt": EvaluationRequest(sut="acc").adapt,
        "OpenAPI EvaluationRequest.adapt":
            _openapi_request(tmp_path)["properties"]["adapt"]["default"],
        "app.cli.evaluate.ADAPT_CHOICES[0]": cli.ADAPT_CHOICES[0],
        "scengen evaluate --adapt": cli_adapt.default,
        "scengen evaluate": _cli_spec(monkeypatch, []).adapt,
    }
    assert {k: v for k, v in defaults.items() if v != default} == {}
    # the same choices, in the same order, wherever one is offered
    choices = {
        "app.services.evaluations.ADAPT": tuple(service.ADAPT),
        "EvaluationRequest.adapt": typing.get_args(
            EvaluationRequest.model_fields["adapt"].annotation),
        "OpenAPI EvaluationRequest.adapt": tuple(
            _openapi_request(tmp_path)["properties"]["adapt"]["enum"]),
        "app.cli.evaluate.ADAPT_CHOICES": tuple(cli.ADAPT_CHOICES),
        "scengen evaluate --adapt": tuple(cli_adapt.choices or ()),
    }
    assert {k: v for k, v in choices.items() if v != service.ADAPT} == {}
    assert set(service.ADAPT) == {"ce", "kernels"}  # what evaluate() accepts


def test_the_cli_reader_sees_a_given_rhw_and_adapt(monkeypatch: pytest.MonkeyPatch) -> None:
    """The control of the CLI's reading above: an rhw or adapt on the command line is what
    reaches the campaign, so the defaults read there are the ones the CLI falls back to."""
    from app.services import evaluations as service

    given = DEFAULT_RHW / 2
    assert _cli_spec(monkeypatch, ["--rhw", str(given)]).rhw == given
    [other] = [a for a in service.ADAPT
               if a != inspect.signature(evaluate).parameters["adapt"].default]
    assert _cli_spec(monkeypatch, ["--adapt", other]).adapt == other
