"""``scengen sample`` has the service's time budget (issue 27 follow-up): a draw that would
take longer than ``--budget`` seconds (default SCENGEN_SYNC_BUDGET_SECONDS) stops with one
line that says how to run it without the limit (before: ``-n 5 -c 'btn>=1'`` ran 73 s and
failed). ``--budget 0`` is no limit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main

RARE = ["sample", "-n", "5", "-c", "btn>=1", "--seed", "1", "-q"]


def _one_line_refusal(err: str, seconds: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("scengen: error: this draw takes longer than the budget of "
                               f"{seconds} s"), err
    assert "--budget 0" in lines[0], err


@pytest.mark.slow
def test_a_rare_draw_past_the_budget_is_refused_in_one_line(
        store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*RARE, "--budget", "1"]) == 2
    _one_line_refusal(capsys.readouterr().err, "1")


@pytest.mark.slow
def test_the_default_budget_is_the_services_setting(
        store: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from app.settings import get_settings

    monkeypatch.setenv("SCENGEN_SYNC_BUDGET_SECONDS", "1.5")
    get_settings.cache_clear()
    assert main(RARE) == 2
    _one_line_refusal(capsys.readouterr().err, "1.5")


def test_budget_zero_is_no_limit(store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A budget that any draw exceeds (1 ns), and the same draw with --budget 0: done."""
    from app.settings import get_settings

    monkeypatch.setenv("SCENGEN_SYNC_BUDGET_SECONDS", "1e-9")
    get_settings.cache_clear()
    cheap = ["sample", "-n", "3", "-c", "ttc<3", "--seed", "1", "-q"]
    assert main(cheap) == 2
    _one_line_refusal(capsys.readouterr().err, "1e-09")
    out = tmp_path / "s.jsonl"
    assert main([*cheap, "--budget", "0", "-o", str(out)]) == 0
    assert len([json.loads(line) for line in out.read_text().splitlines()]) == 3


@pytest.mark.parametrize("given", ["-1", "nan", "inf"])
def test_a_bad_budget_is_one_line(store: Path, capsys: pytest.CaptureFixture[str],
                                  given: str) -> None:
    assert main([*RARE, f"--budget={given}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("scengen: error: --budget: seconds >= 0"), err
