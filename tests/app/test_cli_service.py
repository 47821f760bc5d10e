"""`scengen catalogue create|status|list|export` against a local store."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main


@pytest.mark.slow
def test_create_status_list_export(store: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["catalogue", "create", "--n", "4", "--seed", "3", "--chunk-size", "2",
                 "--constraint", "ttc<3", "--no-score"]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out.strip().splitlines()[-1])
    assert result["status"] == "done"
    assert "4/4" in err and "scenario" in err  # the progress bar (per scenario) on stderr
    assert "P(A): pilot" in err  # and, before it, the P(A) estimate's stages
    cid = result["id"]
    assert main(["catalogue", "status", cid]) == 0
    status = json.loads(capsys.readouterr().out)
    assert status["scenarios_stored"] == 4 and status["constraints"] == ["ttc<3"]
    # issue 25 item 6: what a user looks for first, P(A) last, its replicates not listed
    assert list(status)[:6] == ["id", "status", "progress", "scenarios_done", "n",
                                "constraints"]
    assert list(status)[-1] == "p_region"
    assert "replicates" not in status["p_region"].get("model_interval", {})
    # issue 25 item 3: both intervals, the wider (the model's, for ttc<3) first, each read
    main(["catalogue", "status", cid])
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("P(A) ") and err[0].index("model [") < err[0].index("Monte Carlo")
    assert any(line.startswith("model interval: where P(A) could lie") for line in err)
    assert main(["catalogue", "list"]) == 0
    listing = capsys.readouterr().out.splitlines()
    # issue 25: a header, and the constraints (two catalogues of one n and seed looked alike)
    assert listing[0].split() == ["id", "status", "n", "seed", "constraints", "model",
                                  "created", "(UTC)"]
    line = next(x for x in listing if x.startswith(cid))
    assert line.split()[:5] == [cid, "done", "4", "3", "ttc<3"]
    target = tmp_path / "out.csv"
    assert main(["catalogue", "export", cid, "--format", "csv", "--out", str(target)]) == 0
    assert len(target.read_text().strip().splitlines()) == 5
    # issue 25: an export shows its progress (13 s without a sign before), -q hides it
    err = capsys.readouterr().err
    assert "export csv" in err and "4/4" in err, err
    assert main(["catalogue", "export", cid, "--format", "csv", "--out", str(target),
                 "-q"]) == 0
    assert capsys.readouterr().err == ""


def test_user_errors_are_one_line_and_exit_2(store: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["catalogue", "status", "nope"]) == 2  # no store yet: says where it looked
    assert capsys.readouterr().err.strip().startswith(f"scengen: error: no store at {store}")
    assert main(["catalogue", "create", "--n", "3", "--constraint", "ttc<<3"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scengen: error: constraint") and "\n" not in err
    assert main(["catalogue", "create", "--n", "0"]) == 2
    assert "n must be between 1" in capsys.readouterr().err


@pytest.mark.slow
def test_scenarios_ranked_and_filtered(store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["catalogue", "create", "--n", "5", "--seed", "4", "--chunk-size", "5",
                 "--constraint", "ttc<3", "--no-progress"]) == 0
    cid = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["id"]
    assert main(["catalogue", "scenarios", cid, "--limit", "10"]) == 0
    captured = capsys.readouterr()
    rows = [json.loads(line) for line in captured.out.splitlines()]
    assert json.loads(captured.err.strip().splitlines()[-1])["total"] == 5
    btn = [float(r["btn"]) for r in rows]
    assert btn == sorted(btn, reverse=True)  # the default ranking: btn, highest first
    assert main(["catalogue", "scenarios", cid, "--order-by", "index", "--filter",
                 f"btn_min={btn[1]}"]) == 0
    kept = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert sorted(float(r["btn"]) for r in kept) == sorted(b for b in btn if b >= btn[1])
    assert [r["index"] for r in kept] == sorted(r["index"] for r in kept)
    for argv in (["--filter", "btn>1"], ["--filter", "colour=red"], ["--class", "bad"],
                 ["--order-by", "nope"]):
        assert main(["catalogue", "scenarios", cid, *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("scengen: error:") and "\n" not in err


def test_create_starts_the_pools_warm_up_before_the_catalogue_runs(
        store: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 25: `catalogue create` took 18.5 s from the CLI against 8.4 s over HTTP: the
    service's workers are warm, the CLI's were started only when the first chunk was sent.
    Now their warm-up starts before the catalogue's P(A) estimate (which runs here)."""
    from app.jobs.executors import InlineExecutor
    from app.services import catalogues

    calls: list[str] = []
    monkeypatch.setattr(InlineExecutor, "warm", lambda self: calls.append("warm"))

    def run(ctx: object, catalogue_id: str, **kw: object) -> str:
        calls.append("run")
        return "done"

    monkeypatch.setattr(catalogues, "run", run)
    assert main(["catalogue", "create", "--n", "3", "--seed", "1", "-q"]) == 0
    assert calls == ["warm", "run"]
