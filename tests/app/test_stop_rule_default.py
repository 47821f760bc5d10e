"""The stop rule's default relative half-width is one number everywhere a campaign can
start without ``n`` or ``rhw``: ``sampler.campaign.evaluate()``, ``CampaignResult``,
``POST /evaluations`` (its request model and its OpenAPI schema), the service's use cases
and ``scengen evaluate`` (what it runs with and what its --help says). Each is read from
the place itself, never from the constant, so a default written out again anywhere fails
here."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
from pathlib import Path
from typing import Any

import pytest

from sampler.campaign import DEFAULT_RHW, CampaignResult, evaluate
from tests.app.factories import make_app, make_settings


class _Captured(Exception):
    """Stops ``scengen evaluate`` where it would start the campaign."""


def _cli_rhw(monkeypatch: pytest.MonkeyPatch, argv: list[str]) -> float:
    """The rhw ``scengen evaluate`` hands its campaign (which is not run)."""
    import app.cli.sampling
    from app.cli import build_parser
    from app.services import evaluations as service

    seen: list[float] = []

    def campaign(model: Any, factory: Any, spec: service.CampaignSpec,
                 **_: Any) -> None:
        seen.append(spec.rhw)
        raise _Captured

    monkeypatch.setattr(service, "campaign", campaign)
    monkeypatch.setattr(app.cli.sampling, "_load_model", lambda ref: None)
    args = build_parser().parse_args(["evaluate", "-q", "--sut", "acc", *argv])
    with pytest.raises(_Captured):
        args.func(args)
    [rhw] = seen
    return rhw


def _evaluate_help() -> str:
    from app.cli import build_parser

    parser = build_parser()
    [sub] = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return " ".join(sub.choices["evaluate"].format_help().split())


def test_every_default_rhw_is_the_samplers(monkeypatch: pytest.MonkeyPatch,
                                           tmp_path: Path) -> None:
    from app.routes.evaluations import EvaluationRequest
    from app.services import evaluations as service

    openapi = make_app(make_settings(tmp_path)).openapi()
    defaults = {
        "evaluate()": inspect.signature(evaluate).parameters["rhw"].default,
        "CampaignResult.rhw_target": {f.name: f.default for f in
                                      dataclasses.fields(CampaignResult)}["rhw_target"],
        "EvaluationRequest.rhw": EvaluationRequest(sut="acc").rhw,
        "OpenAPI EvaluationRequest.rhw": openapi["components"]["schemas"][
            "EvaluationRequest"]["properties"]["rhw"]["default"],
        "app.services.evaluations.DEFAULT_RHW": service.DEFAULT_RHW,
        "evaluations.create()": inspect.signature(service.create).parameters["rhw"].default,
        "evaluations.validate()":
            inspect.signature(service.validate).parameters["rhw"].default,
        "scengen evaluate": _cli_rhw(monkeypatch, []),
    }
    assert {k: v for k, v in defaults.items() if v != DEFAULT_RHW} == {}
    assert f"with at least 10 collisions (default {DEFAULT_RHW})" in _evaluate_help()


def test_the_cli_reader_sees_a_given_rhw(monkeypatch: pytest.MonkeyPatch) -> None:
    """The control of the CLI's reading above: an rhw on the command line is what reaches
    the campaign, so the default read there is the one the CLI falls back to."""
    given = DEFAULT_RHW / 2
    assert _cli_rhw(monkeypatch, ["--rhw", str(given)]) == given
