"""Recorded cut-ins scored through the service: the 208 real TNO cut-ins (nobody crashed
in them) posted to ``POST /risk`` as concrete scenarios all come back ``no_conflict`` or
``preventable`` (issue 11); the CLI writes the same scenarios and scores them alike."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from datasets.egocentric import egocentric_to_scenarios
from datasets.embedded import load_default_events
from riskcore.criticality import evaluate_criticality


@pytest.mark.slow
def test_real_tno_cut_ins_through_the_scenario_api(client: Any) -> None:
    scenarios = egocentric_to_scenarios(load_default_events())
    assert len(scenarios) == 208
    counts: dict[str, int] = {}
    for event_id, scenario in scenarios.items():
        resp = client.post("/risk", json=scenario.to_dict())
        assert resp.status_code == 200, (event_id, resp.text)
        body = resp.json()
        assert body["criticality_error"] is None, (event_id, body["criticality_error"])
        crit = body["criticality"]
        counts[crit["class"]] = counts.get(crit["class"], 0) + 1
        assert crit["r157_cc_collision"] is False, event_id
    assert sum(counts.values()) == 208
    assert set(counts) <= {"no_conflict", "preventable"}, counts


def test_posted_scenario_carries_the_same_record_as_riskcore(client: Any) -> None:
    scenario = next(iter(egocentric_to_scenarios(load_default_events()).values()))
    body = client.post("/risk", json=scenario.to_dict()).json()
    expected = json.loads(json.dumps(evaluate_criticality(scenario).to_record(),
                                     allow_nan=True).replace("Infinity", '"Infinity"'))
    assert body["criticality"] == expected


def test_posted_scenario_without_a_cut_in(client: Any) -> None:
    scenario = next(iter(egocentric_to_scenarios(load_default_events()).values())).to_dict()
    cutter = scenario["objects"][0]
    cutter["y"] = [cutter["y"][0]] * len(cutter["y"])  # no lateral movement at all
    crit = client.post("/risk", json=scenario).json()["criticality"]
    assert crit["t_p"] is None and crit["class"] == "no_conflict", crit
    scenario["objects"] = []  # nothing to cut in: no record, and the reason
    body = client.post("/risk", json=scenario).json()
    assert body["criticality"] is None
    assert "cutter" in body["criticality_error"], body["criticality_error"]


def test_cli_writes_recorded_events_as_scenarios(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    assert main(["data", "scenarios", "-o", str(tmp_path / "out")]) == 0
    files = sorted((tmp_path / "out").glob("*.json"))
    assert len(files) == 208
    assert "208 recorded events" in capsys.readouterr().out
    assert main(["risk", str(files[0]), "--summary"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["criticality"]["class"] in {"no_conflict", "preventable"}
