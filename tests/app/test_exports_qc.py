"""The ASAM Quality Checker (OpenSCENARIO XML and OpenDRIVE bundles) on our exports.

The checker bundles live in their own environment (``make qc-env`` makes ``.venv-qc``; ``make
test`` does it first): they pin numpy < 2. ``$SCENGEN_QC_PYTHON`` may point at another
interpreter that has them. Without one the tests skip and say how to get it.
"""

from __future__ import annotations

import json
import os
import subprocess
import zipfile
from pathlib import Path
from typing import Any

import pytest

from app.exports import build_manifest, export_catalogue
from riskcore.criticality import evaluate_criticality
from sampler.scenario.builder import build_scenario

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "scripts" / "qc_check.py"
PARAMS = [
    {"p_y1": -0.05, "p_t": 2.0, "p_a1": 0.5, "p_a2": 0.25, "p_a3": 1.0, "p_v0": 25.0,
     "dv": 4.0, "gap": 2.0},
    {"p_y1": 0.05, "p_t": 1.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0, "p_v0": 31.0,
     "dv": -1.0, "gap": 20.0},  # opening: ttc = inf
]


def _qc_python() -> Path | None:
    value = os.environ.get("SCENGEN_QC_PYTHON")
    path = Path(value) if value else REPO / ".venv-qc" / "bin" / "python"
    return path if path.is_file() else None


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    python = _qc_python()
    if python is None:
        pytest.skip("the ASAM Quality Checker environment is missing: run `make qc-env` "
                    "(or set SCENGEN_QC_PYTHON)")
    tmp = tmp_path_factory.mktemp("qc")
    manifest = build_manifest(seed=1, model_hash=None, sampler_settings={}, constraints=[],
                              p_region=None)
    scenarios = [build_scenario(p, seed=i) for i, p in enumerate(PARAMS)]
    # the criticality fields go into the files as parameter declarations
    items = [(s, {"exposure_weight": 0.5, **evaluate_criticality(s).to_record()})
             for s in scenarios]
    files: list[Path] = []
    for mode in ("test", "replay"):
        folder = tmp / mode
        path = export_catalogue("xosc", items, manifest, tmp / f"{mode}.zip", mode=mode)
        with zipfile.ZipFile(path) as zf:
            zf.extractall(folder)
        files += [folder / "scenario_0000000.xosc", folder / "scenario_0000001.xosc"]
        if mode == "test":
            files += [folder / "road.xodr", folder / "cutin_logical.xosc",
                      folder / "cutin_distribution.xosc",
                      folder / "catalogs" / "scengen_cutter_trajectories.xosc"]
    # a deliberately broken copy: the checker must find its dangling references
    broken = tmp / "test" / "broken.xosc"
    broken.write_text(files[0].read_text().replace('entityRef="cutter"', 'entityRef="nobody"'))
    files.append(broken)
    proc = subprocess.run([str(python), str(SCRIPT), *map(str, files)], capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out: dict[str, Any] = json.loads(proc.stdout)
    return {Path(k).relative_to(tmp).as_posix(): v for k, v in out.items()}


def test_quality_checker_finds_no_errors_in_the_exports(report: dict[str, Any]) -> None:
    checked = [name for name in report if name != "test/broken.xosc"]
    assert len(checked) == 8
    for name in checked:
        errors = [i for i in report[name]["issues"] if i["level"] == "error"]
        assert errors == [], (name, errors)
        # the bundle did run its checks (not all skipped for a failed precondition)
        assert "completed" in report[name]["checkers"].values(), name
    warnings = sorted({(name, i["checker"], i["description"]) for name in checked
                       for i in report[name]["issues"] if i["level"] == "warning"})
    print(f"quality-checker warnings ({len(warnings)}):")  # listed in the test log
    for warning in warnings:
        print("  ", *warning)


def test_quality_checker_does_report_a_broken_file(report: dict[str, Any]) -> None:
    errors = [i for i in report["test/broken.xosc"]["issues"] if i["level"] == "error"]
    assert {i["checker"] for i in errors} == {
        "check_asam_xosc_reference_control_resolvable_entity_references"}
