"""``scengen data ...`` through app.cli.main: outputs, files, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main
from datasets.table import TABLE_COLUMNS, read_table
from tests.datasets.highd_factory import changing, make_recording, p_for_lane_change, straight
from tests.datasets.test_tno import _tno


def test_describe_default_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "describe"]) == 0
    out = capsys.readouterr().out
    assert "embedded table" in out and "cut-ins" in out
    for col in TABLE_COLUMNS:
        assert f"\n{col} " in out, col


def test_synth_extract_describe(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = tmp_path / "rec"
    assert main(["data", "synth", "-o", str(d), "--seed", "2", "--minutes", "1",
                 "--vehicles", "70"]) == 0
    assert "SYNTHETIC" in capsys.readouterr().out
    assert (d / "01_groundtruth_SYNTHETIC.csv").is_file()
    for suffix in ("parquet", "csv"):
        out = tmp_path / f"table.{suffix}"
        assert main(["data", "extract", "--format", "highd", str(d), "-o", str(out),
                     "-q"]) == 0
        assert "cut-ins extracted" in capsys.readouterr().out
        assert list(read_table(out).columns) == list(TABLE_COLUMNS)
    assert main(["data", "describe", str(tmp_path / "table.csv")]) == 0
    assert "p_y1" in capsys.readouterr().out


def test_extract_highd_hand_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from datasets.highd import write_highd

    p = p_for_lane_change(left=True, p_t=2.0, v=26.0)
    write_highd(make_recording([changing(1, 2, 6, 150.0, 3.0, p),
                                straight(2, 2, 5, 20.0, 30.0)]), tmp_path)
    out = tmp_path / "t.parquet"
    assert main(["data", "extract", "--format", "highd",
                 str(tmp_path / "07_tracks.csv"), "-o", str(out), "-q"]) == 0
    assert len(read_table(out)) == 1
    # the exposure beside the table: two vehicles tracked 300 frames each at 25 Hz
    assert "vehicle-hours" in capsys.readouterr().out
    side = json.loads((tmp_path / "t.parquet.exposure.json").read_text())
    assert side["hours"] == pytest.approx(600 / 25 / 3600, rel=1e-12)
    assert side["n_events"] == 1 and side["km"] > 0.3588  # vehicle 2 alone: 358.8 m


def test_fit_reads_the_exposure_beside_the_table(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from tests.sampler.factories import synthetic_parameter_table

    table = tmp_path / "t.parquet"
    synthetic_parameter_table(120, seed=3).to_parquet(table, index=False)
    (tmp_path / "t.parquet.exposure.json").write_text(json.dumps(
        {"n_events": 7, "hours": 2.5, "km": 250.0, "source": "highD test"}))
    model = tmp_path / "m.json"
    assert main(["fit", str(table), "-o", str(model), "--k-max", "1", "--n-init", "1",
                 "--bootstrap", "0"]) == 0
    assert "48 cut-ins per hour" in capsys.readouterr().out  # 120 rows / 2.5 h
    exp = json.loads(model.read_text())["exposure"]
    assert exp == {"n_events": 120, "hours": 2.5, "km": 250.0, "source": "highD test"}


@pytest.mark.slow
def test_convert_tno_and_fit_surfaces(tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "src"
    src.mkdir()
    (src / "cut-in.json").write_text(json.dumps(_tno()))
    (src / "LICENSE").write_text("MIT License\nCopyright (c) 2021 ErwindeGelder\n")
    out = tmp_path / "out" / "events.csv"
    assert main(["data", "convert-tno", "--input", str(src / "cut-in.json"),
                 "-o", str(out)]) == 0
    assert "1 events read, 1 kept, 0 left out" in capsys.readouterr().out
    assert (out.parent / "LICENSE").read_text().startswith("MIT License")
    assert "627aa1e" in (out.parent / "PROVENANCE.md").read_text()
    table = tmp_path / "t.csv"
    assert main(["data", "extract", "--format", "egocentric", str(out), "-o", str(table),
                 "-q"]) == 0
    surf = tmp_path / "s.json"
    assert main(["data", "fit-surfaces", "-o", str(surf)]) == 0  # embedded events
    assert json.loads(surf.read_text())["interim"] is False


@pytest.mark.parametrize(("argv", "fragment"), [
    (["data", "extract", "--format", "egocentric", "/nonexistent.csv", "-o", "/tmp/x.csv"],
     "/nonexistent.csv: no such file"),
    (["data", "extract", "--format", "highd", "/nonexistent_dir", "-o", "/tmp/x.csv"],
     "not a highD folder"),
    (["data", "describe", "/nonexistent.parquet"], "no such file"),
    (["data", "convert-tno", "--input", "/nonexistent.json", "-o", "/tmp/x.parquet"],
     "LICENSE: missing"),
    (["data", "synth", "-o", "/tmp/never", "--seed", "1", "--lanes", "9"],
     "lanes_per_direction"),
])
def test_user_errors_are_one_line_exit_2(argv: list[str], fragment: str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("scengen: error:") and fragment in err
    assert err.count("\n") == 1
