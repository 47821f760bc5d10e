"""The vectorised risk report equals riskcore's own element-by-element ``to_dict`` (the
slow reference), up to the JSON convention (+inf kept instead of null)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from app.domain.risk import risk_report
from riskcore import evaluate_scenario
from sampler.scenario.builder import build_scenario
from tests.sampler.factories import base_params


def _same(fast: Any, slow: Any, where: str = "") -> None:
    if isinstance(slow, dict):
        assert set(fast) >= set(slow), where
        for k, v in slow.items():
            _same(fast[k], v, f"{where}.{k}")
    elif isinstance(slow, list):
        assert isinstance(fast, list) and len(fast) == len(slow), where
        for i, (a, b) in enumerate(zip(fast, slow, strict=True)):
            _same(a, b, f"{where}[{i}]")
    elif slow is None and isinstance(fast, float):
        assert math.isinf(fast), where  # riskcore writes +inf as null
    else:
        assert fast == slow, where


def test_report_matches_riskcore_to_dict() -> None:
    scenario = build_scenario(base_params(dv=6.0, gap=4.0))  # adaptive duration
    risk = evaluate_scenario(scenario)
    slow = risk.to_dict()
    fast = risk_report(risk, samples=True)
    _same(fast.series, slow["series"], "series")
    _same(fast.objects, slow["objects"], "objects")
    assert fast.evasion_bits == slow["evasion_bits"]
    assert fast.settings == slow["settings"] and fast.surfaces == slow["surfaces"]
    labels = np.array(fast.objects[0]["samples"]["evasion"], dtype=object)
    assert (labels != None).any() and (labels == None).any()  # noqa: E711  both kinds tested
    brief = risk_report(risk)
    assert "samples" not in brief.objects[0] and brief.series == fast.series
