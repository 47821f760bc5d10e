"""A criticality region sampled by subset-is still gets its model interval and rates (the
pooled stage must take the rare path for subset-is as for subset: plain draws of the
replicates' average never reach btn > 0.7 and the command failed after its samples)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main


@pytest.mark.slow
def test_sample_in_a_btn_region_reports_both_intervals(
        store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.jsonl"
    assert main(["sample", "-n", "10", "-c", "btn>0.7", "--seed", "2", "-q",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "subset-is" in err, err
    assert "rate per hour" in err and "model [" in err, err
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 10
