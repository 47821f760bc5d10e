"""``scengen fit`` and ``scengen sample`` through app.cli.main."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main
from datasets.cutin_model import PARAM_NAMES
from sampler import CutInGMM
from tests.sampler.factories import synthetic_parameter_table


@pytest.fixture(scope="module")
def model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("cli")
    table = d / "table.csv"
    synthetic_parameter_table(200, seed=1).to_csv(table, index=False)
    out = d / "model.json"
    assert main(["fit", str(table), "-o", str(out), "--k-max", "3", "--n-init", "1"]) == 0
    return out


@pytest.mark.slow
def test_fit_prints_bic_curve_and_report(model_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    table = model_path.parent / "table.csv"
    out = model_path.parent / "m2.json"
    assert main(["fit", str(table), "-o", str(out), "--k-max", "2", "--n-init", "1"]) == 0
    text = capsys.readouterr().out
    assert "K= 1" in text and "K= 2" in text and "<- chosen" in text
    assert "held-out" in text and "KS statistic" in text and "outside physical bounds" in text
    model = CutInGMM.load(out)
    assert model.n_components_ in (1, 2)


@pytest.mark.slow
def test_sample_writes_jsonl_and_summary(model_path: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.jsonl"
    summary = tmp_path / "summary.json"
    rc = main(["sample", str(model_path), "--constraint", "ttc<8", "-n", "20", "--seed", "1",
               "-o", str(out), "--summary-json", str(summary), "-q", "--scenarios"])
    assert rc == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert len(lines) == 20 and [r["index"] for r in lines] == list(range(20))
    for r in lines:
        assert set(r["params"]) == set(PARAM_NAMES)
        assert r["derived"]["ttc"] < 8
        assert r["exposure_weight"] > 0 and r["scenario"]["schema"].startswith("scengen")
    err = capsys.readouterr().err
    assert "P(A)=" in err and "seed 1" in err
    s = json.loads(summary.read_text())
    assert s["seed"] == 1 and s["constraints"][0]["name"] == "ttc"
    # same seed, same lines
    out2 = tmp_path / "s2.jsonl"
    main(["sample", str(model_path), "-c", "ttc<8", "-n", "20", "--seed", "1", "-o", str(out2),
          "-q", "--scenarios"])
    assert out2.read_text() == out.read_text()


@pytest.mark.slow
def test_sample_with_score(model_path: Path, tmp_path: Path) -> None:
    out = tmp_path / "scored.jsonl"
    assert main(["sample", str(model_path), "-c", "ttc<4", "-n", "3", "--seed", "2",
                 "--score", "-o", str(out), "-q"]) == 0
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    assert all(r["class"] and r["btn"] is not None for r in rows)  # the flat record
    # the Wagner scan is asked for, not always made
    assert all(r["risk_peak"] is None and r["alarm_time"] is None for r in rows)
    assert all(r["support"] in ("inside", "near", "extrapolated") for r in rows)
    assert all("support" not in r["derived"] for r in rows)
    # one time axis: t_p, t_cross (record) and the derived crossing are scenario time
    assert all(abs(r["t_cross"] - r["derived"]["t_cross"]) < 2e-3 for r in rows)
    assert all(r["t_p"] < r["t_cross"] for r in rows)
    scanned = tmp_path / "scanned.jsonl"
    assert main(["sample", str(model_path), "-c", "ttc<4", "-n", "3", "--seed", "2",
                 "--score", "--wagner-scan", "-o", str(scanned), "-q"]) == 0
    rows = [json.loads(x) for x in scanned.read_text().splitlines()]
    assert all(0.0 <= r["risk_peak"] <= 1.0 for r in rows)


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [(["sample", "{model}", "-c", "speed<3"], "valid names"),
     (["sample", "{model}", "-c", "ttc<3", "-n", "0"], "n: expected"),
     (["sample", "{dir}/missing.json"], "cannot read"),
     (["sample", "{model}", "-c", "gap<5", "-c", "gap>6", "-n", "2"], "empty"),
     (["fit", "{dir}/missing.csv", "-o", "{dir}/x.json"], "no such file"),
     (["fit", "{dir}/table.txt", "-o", "{dir}/x.json"], ".csv or .parquet"),
     (["fit", "{dir}/bad.csv", "-o", "{dir}/x.json"], "missing column")],
)
def test_user_errors_are_one_line_exit_2(model_path: Path, argv: list[str], fragment: str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    d = model_path.parent
    (d / "bad.csv").write_text("a,b\n1,2\n")
    args = [a.format(model=model_path, dir=d) for a in argv]
    if args[0] == "sample":
        args.append("-q")
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scengen: error:") and fragment in err
    assert len(err.splitlines()) == 1
