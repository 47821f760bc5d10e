"""``scengen risk``: JSON out, settings overrides, and one-line errors for bad input."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from app.cli import main


def _scenario(n: int = 21) -> dict[str, Any]:
    t = [round(0.1 * i, 10) for i in range(n)]

    def track(tid: str, x0: float, v: float) -> dict[str, Any]:
        return {"id": tid, "length": 4.5, "width": 1.8, "x": [x0 + v * s for s in t],
                "y": [0.0] * n, "psi": [0.0] * n, "v": [v] * n}

    return {"schema": "scengen.concrete-scenario/1", "t": t, "ego": track("ego", 0.0, 21.0),
            "objects": [track("lead", 30.0, 10.0)], "params": {}, "seed": None,
            "provenance": {}}


def _write(tmp_path: Path, data: Any, text: str | None = None) -> str:
    path = tmp_path / "scenario.json"
    path.write_text(text if text is not None else json.dumps(data))
    return str(path)


def test_prints_the_result_as_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path, _scenario())
    assert main(["risk", path]) == 0  # the summary report by default (issue 13)
    brief = json.loads(capsys.readouterr().out)
    assert "samples" not in brief["objects"][0]
    assert main(["risk", path, "--samples"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "scengen.scenario-risk/1"
    assert len(out["series"]["r_dep"]) == 21 and brief["series"] == out["series"]
    samples = out["objects"][0]["samples"]
    assert len(samples["ttr"]) == 21 and len(samples["ttr"][0]) == 100
    assert len(samples["weight"][0]) == len(samples["evasion"][0]) == 100
    assert out["summary"]["risk"] == max(out["series"]["r_dep"])
    assert out["settings"]["horizon"] == 3.0


def test_pretty_summary_and_overrides(tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path, _scenario())
    assert main(["risk", path, "--pretty", "--horizon", "2", "--n-a", "4", "--t-pnr", "0.3",
                 "--brake-max", "9", "--samples"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("{\n  ")
    out = json.loads(text)
    assert out["settings"]["horizon"] == 2.0 and out["settings"]["n_a"] == 4
    assert out["settings"]["t_pnr"] == 0.3 and out["settings"]["brake_max"] == 9.0
    assert len(out["objects"][0]["samples"]["ttr"][0]) == 40
    assert main(["risk", path, "--summary"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert set(summary) >= {"risk", "risk_ind", "min_ttr", "min_ttc", "min_wttc", "min_thw"}


def _set(path: list[Any], value: Any) -> Callable[[dict[str, Any]], None]:
    def mutate(d: dict[str, Any]) -> None:
        target: Any = d
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return mutate


BAD: list[tuple[str, Callable[[dict[str, Any]], None], str]] = [
    ("nan", _set(["objects", 0, "x", 3], math.nan), "objects[0].x[3]"),
    ("infinity", _set(["ego", "v", 0], math.inf), "ego.v[0]"),
    ("ragged", lambda d: d["objects"][0]["v"].pop(), "objects[0].v: has 20 values"),
    ("negative size", _set(["ego", "length"], -4.5), "ego.length"),
    ("zero width", _set(["objects", 0, "width"], 0), "objects[0].width"),
    ("non-increasing t", _set(["t", 5], 0.3), "t[5]"),
    ("unknown top field", _set(["colour"], "red"), "unknown field(s) colour"),
    ("unknown track field", _set(["ego", "speed"], 3), "ego: unknown field(s) speed"),
    ("negative speed", _set(["objects", 0, "v", 2], -1.0), "objects[0].v[2]"),
    ("missing ego", lambda d: d.pop("ego"), "ego: missing"),
]


@pytest.mark.parametrize(("name", "mutate", "needle"), BAD, ids=[b[0] for b in BAD])
def test_bad_scenarios_give_one_line_naming_the_field(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str,
        mutate: Callable[[dict[str, Any]], None], needle: str) -> None:
    data = _scenario()
    mutate(data)
    path = _write(tmp_path, data)  # json.dumps writes NaN / Infinity literals
    assert main(["risk", path]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("scengen: error: ")
    assert needle in lines[0]
    assert path in lines[0]


@pytest.mark.parametrize(("text", "args", "needle"), [
    ("{", [], "not valid JSON"),
    ("[1, 2]", [], "expected a JSON object"),
    (None, ["--t-pnr", "2.5"], "t_pnr"),
    (None, ["--horizon", "0.25"], "horizon"),
    (None, ["--surfaces", "/nonexistent/s.json"], "/nonexistent/s.json"),
])
def test_other_user_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                           text: str | None, args: list[str], needle: str) -> None:
    path = _write(tmp_path, _scenario(), text)
    assert main(["risk", path, *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("scengen: error: ") and needle in err[0]


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["risk", str(tmp_path / "nope.json")]) == 2
    assert "nope.json" in capsys.readouterr().err
