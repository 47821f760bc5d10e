"""Catalogue exports: hand-made scenarios with hand-known rows, files and trajectories.

The scenarios are built by hand (ego plus one cut-in at known positions), never by the
sampler. Every expected value below is written out, not computed by app.exports.
"""

from __future__ import annotations

import csv
import gc
import importlib.metadata
import io
import json
import math
import re
import weakref
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree

import app.exports._tabular as tabular
from app.exports import (
    EXPORT_FORMATS,
    ExportError,
    build_manifest,
    export_catalogue,
    read_jsonl,
    read_jsonl_manifest,
    scenario_row,
)
from riskcore.scenario import ConcreteScenario, Track

# --------------------------------------------------------------------------- factories

PARAMS_A = {"p_y1": -0.05, "p_t": 2.0, "p_a1": 0.5, "p_a2": 0.25, "p_a3": 1.0,
            "p_v0": 25.0, "dv": 4.0, "gap": 12.0}  # ttc = 12 / 4 = 3 s
PARAMS_B = {"p_y1": 0.04, "p_t": 1.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
            "p_v0": 31.0, "dv": -1.0, "gap": 20.0}  # opening: ttc = inf

# a scored record's summary: the criticality record (hand-made values), the exposure weight
# and the error
SUMMARY_A = {"exposure_weight": 0.01, "t_p": 2.75, "t_cross": 3.5, "ttr_true": 1.2,
             "ttr_manoeuvre": "brake", "a_req": 3.25, "btn": 0.43, "class": "preventable",
             "none_collision": True, "none_impact_speed": 4.0, "none_min_gap": 0.0,
             "r157_cc_collision": False, "r157_cc_impact_speed": 0.0,
             "r157_cc_min_gap": 1.5, "r157_cc_t_brake": 3.3, "rss_collision": False,
             "rss_impact_speed": 0.0, "rss_min_gap": 2.25, "rss_t_brake": 3.1,
             "r_dep_tp": 0.125, "r_ind_tp": 0.25, "r_dep_cross": 0.375, "r_ind_cross": 0.5,
             "r_dep_tp_r157": 0.0625, "r_ind_tp_r157": 0.125, "r_dep_cross_r157": 0.25,
             "r_ind_cross_r157": 0.375, "alarm_time": 0.625, "risk_peak": 0.4, "error": None}
# an opening cut-in: no collision course (ttr_true +inf), nothing braked, never alarmed
SUMMARY_B = {"exposure_weight": 2.0, "t_p": 2.5, "t_cross": 3.0, "ttr_true": math.inf,
             "ttr_manoeuvre": None, "a_req": 0.0, "btn": 0.0, "class": "no_conflict",
             "none_collision": False, "none_impact_speed": 0.0, "none_min_gap": 8.0,
             "r157_cc_collision": False, "r157_cc_impact_speed": 0.0,
             "r157_cc_min_gap": 8.0, "r157_cc_t_brake": None, "rss_collision": False,
             "rss_impact_speed": 0.0, "rss_min_gap": 8.0, "rss_t_brake": None,
             "r_dep_tp": 0.0, "r_ind_tp": 0.0, "r_dep_cross": 0.0, "r_ind_cross": 0.0,
             "r_dep_tp_r157": 0.0, "r_ind_tp_r157": 0.0, "r_dep_cross_r157": 0.0,
             "r_ind_cross_r157": 0.0, "alarm_time": None, "risk_peak": 0.0, "error": None}


def _track(track_id: str, length: float, width: float, x: list[float], y: list[float],
           psi: list[float], v: list[float]) -> Track:
    return Track(track_id, length, width, x=np.array(x), y=np.array(y), psi=np.array(psi),
                 v=np.array(v))


def scenario_a() -> ConcreteScenario:
    """Ego at 30 m/s in its lane; a cut-in from the left lane, 4 steps of 0.1 s from t=0."""
    return ConcreteScenario(
        t=np.array([0.0, 0.1, 0.2, 0.3]),
        ego=_track("ego", 4.5, 1.8, [0.0, 3.0, 6.0, 9.0], [0.0] * 4, [0.0] * 4, [30.0] * 4),
        objects=(_track("cutin", 4.0, 1.7, [20.0, 22.5, 25.0, 27.5],
                        [3.75, 3.5, 3.25, 3.0], [-0.1] * 4, [25.0] * 4),),
        params=dict(PARAMS_A), seed=7, provenance={"scenario_id": "a"},
    )


def scenario_b() -> ConcreteScenario:
    """A cut-in from the right whose time grid starts at t = 2 s (3 steps of 0.5 s)."""
    return ConcreteScenario(
        t=np.array([2.0, 2.5, 3.0]),
        ego=_track("ego", 5.0, 2.0, [100.0, 115.0, 130.0], [0.0] * 3, [0.0] * 3, [30.0] * 3),
        objects=(_track("car 1", 4.25, 1.75, [110.0, 126.0, 142.0], [-3.5, -2.5, -1.5],
                        [0.2, 0.25, 0.125], [32.0] * 3),),
        params=dict(PARAMS_B), seed=8, provenance={"scenario_id": "b"},
    )


def items() -> list[tuple[ConcreteScenario, dict[str, Any]]]:
    return [(scenario_a(), dict(SUMMARY_A)), (scenario_b(), dict(SUMMARY_B))]


def manifest() -> dict[str, Any]:
    return build_manifest(seed=42, model_hash="sha256:abc", sampler_settings={"method": "mcmc"},
                          constraints=["ttc<3"],
                          p_region={"estimate": 0.0125, "ci": [0.01, 0.015]},
                          extra={"catalogue_id": "cat-1"})


EXPECTED_COLUMNS = [
    "scenario_id", "seed",
    "p_y1", "p_t", "p_a1", "p_a2", "p_a3", "p_v0", "dv", "gap",
    "ttc", "duration", "dt", "n_steps", "n_objects",
    "exposure_weight",
    "t_p", "t_cross", "ttr_true", "ttr_manoeuvre", "a_req", "btn", "class",
    "none_collision", "none_impact_speed", "none_min_gap",
    "r157_cc_collision", "r157_cc_impact_speed", "r157_cc_min_gap", "r157_cc_t_brake",
    "rss_collision", "rss_impact_speed", "rss_min_gap", "rss_t_brake",
    "r_dep_tp", "r_ind_tp", "r_dep_cross", "r_ind_cross",
    "r_dep_tp_r157", "r_ind_tp_r157", "r_dep_cross_r157", "r_ind_cross_r157",
    "alarm_time", "risk_peak", "error",
]
ROW_A = {"scenario_id": "a", "seed": 7, **PARAMS_A, "ttc": 3.0, "duration": 0.3, "dt": 0.1,
         "n_steps": 4, "n_objects": 1, **SUMMARY_A}
ROW_B = {"scenario_id": "b", "seed": 8, **PARAMS_B, "ttc": math.inf, "duration": 1.0,
         "dt": 0.5, "n_steps": 3, "n_objects": 1, **SUMMARY_B}


def _export(tmp_path: Path, fmt: str, name: str | None = None,
            data: list[tuple[ConcreteScenario, dict[str, Any]]] | None = None) -> Path:
    out = tmp_path / (name or f"catalogue.{'zip' if fmt in ('xosc', 'commonroad') else fmt}")
    return export_catalogue(fmt, data if data is not None else items(), manifest(), out)


def _assert_close_row(actual: dict[str, Any], expected: dict[str, Any]) -> None:
    assert list(actual) == list(expected)
    for key, value in expected.items():
        if isinstance(value, float):
            assert actual[key] == pytest.approx(value, rel=1e-12), key
        else:
            assert actual[key] == value, key


# --------------------------------------------------------------------------- scenario_row


def test_formats_are_the_five_documented_ones() -> None:
    assert EXPORT_FORMATS == ("jsonl", "csv", "parquet", "xosc", "commonroad")


def test_row_has_parameters_then_derived_then_scores_in_fixed_order() -> None:
    row = scenario_row(scenario_a(), SUMMARY_A)
    assert list(row) == EXPECTED_COLUMNS
    _assert_close_row(row, ROW_A)
    assert row["ttc"] == 3.0  # 12 m / 4 m/s


def test_row_of_an_opening_cut_in_has_infinite_ttc_and_keeps_none() -> None:
    row = scenario_row(scenario_b(), SUMMARY_B)
    assert row["ttc"] == math.inf
    assert row["ttr_manoeuvre"] is None
    assert row["r157_cc_t_brake"] is None
    assert row["ttr_true"] == math.inf


def test_row_without_scores_has_empty_score_columns_and_extras_sorted_last() -> None:
    sc = scenario_a()
    row = scenario_row(sc, {"zeta": 1, "alpha": "x"})
    assert list(row) == [*EXPECTED_COLUMNS, "alpha", "zeta"]
    assert row["risk_peak"] is None and row["exposure_weight"] is None
    assert row["class"] is None and row["error"] is None
    assert row["alpha"] == "x" and row["zeta"] == 1


def test_row_scenario_id_from_summary_wins_over_provenance() -> None:
    assert scenario_row(scenario_a(), {"scenario_id": 17})["scenario_id"] == 17


def test_row_of_a_recorded_drive_without_parameters() -> None:
    sc = scenario_a()
    drive = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects)
    row = scenario_row(drive, {})
    assert row["p_y1"] is None and row["gap"] is None and row["ttc"] is None
    assert row["scenario_id"] is None and row["seed"] is None


def test_row_accepts_numpy_scalars_as_plain_numbers() -> None:
    row = scenario_row(scenario_a(), {"risk_peak": np.float64(0.5), "n_hits": np.int64(3)})
    assert type(row["risk_peak"]) is float and row["risk_peak"] == 0.5
    assert type(row["n_hits"]) is int and row["n_hits"] == 3


@pytest.mark.parametrize(
    ("summary", "message"),
    [
        ({"btn": [0.1, 0.2]}, "summary['btn']: expected a number, string or None, got list"),
        ({"ttc": 2.0}, "column 'ttc' = 2.0 conflicts with the value 3.0"),
        ({3: 1.0}, "summary: keys must be non-empty strings"),
        ({"index": 1}, "summary['index']: the column name 'index' is reserved"),
        ({"file": "x"}, "summary['file']: the column name 'file' is reserved"),
    ],
)
def test_row_bad_summary_is_a_clear_error(summary: dict[Any, Any], message: str) -> None:
    with pytest.raises(ExportError, match=re.escape(message)):
        scenario_row(scenario_a(), summary)


def test_row_rejects_a_parameter_with_a_reserved_name() -> None:
    sc = scenario_a()
    odd = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects, params={"index": 1.0})
    message = "params['index']: the column name 'index' is reserved"
    with pytest.raises(ExportError, match=re.escape(message)):
        scenario_row(odd, {})


def test_row_summary_may_repeat_a_derived_value_when_it_agrees() -> None:
    assert scenario_row(scenario_a(), {"ttc": 3.0})["ttc"] == 3.0


# --------------------------------------------------------------------------- manifest


def test_manifest_has_provenance_versions_and_no_clock() -> None:
    m = manifest()
    assert m["format"] == "scengen.catalogue-manifest/1"
    assert m["seed"] == 42
    assert m["model_hash"] == "sha256:abc"
    assert m["sampler_settings"] == {"method": "mcmc"}
    assert m["constraints"] == ["ttc<3"]
    assert m["p_region"] == {"estimate": 0.0125, "ci": [0.01, 0.015]}
    assert m["catalogue_id"] == "cat-1"
    assert set(m["versions"]) == {"scengen", "numpy", "scipy", "pandas", "scikit-learn",
                                  "emcee", "numba", "fastapi", "sqlalchemy", "distributed",
                                  "scenariogeneration"}
    assert m["versions"]["numpy"] == np.__version__
    assert m["versions"]["scenariogeneration"] == importlib.metadata.version(
        "scenariogeneration")
    assert "no wall-clock timestamp" in m["note"]
    assert "created_at" not in m
    assert manifest() == m  # deterministic


def test_manifest_takes_a_timestamp_only_when_given() -> None:
    m = build_manifest(seed=None, model_hash=None, sampler_settings={}, constraints="ttc<3",
                       p_region=0.5, extra={"created_at": "2026-01-02T03:04:05"})
    assert m["created_at"] == "2026-01-02T03:04:05"
    assert m["constraints"] == ["ttc<3"]
    assert m["p_region"] == 0.5


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seed": "7"}, "seed: expected an integer or None"),
        ({"seed": True}, "seed: expected an integer or None"),
        ({"sampler_settings": [1]}, "sampler_settings: expected a mapping"),
        ({"constraints": [3]}, r"constraints\[0\]: expected a string"),
        ({"p_region": "high"}, "p_region: expected a number, mapping or None"),
        ({"extra": {"seed": 1}}, r"extra\['seed'\]: would replace a standard manifest field"),
        ({"sampler_settings": {"f": object()}}, "sampler_settings.f: expected JSON-able data"),
    ],
)
def test_manifest_bad_fields_are_named(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {"seed": 1, "model_hash": "h", "sampler_settings": {},
                            "constraints": [], "p_region": None}
    args.update(kwargs)
    with pytest.raises(ExportError, match=message):
        build_manifest(**args)


# --------------------------------------------------------------------------- jsonl


def _reject_constant(name: str) -> None:
    raise AssertionError(f"non-standard JSON constant {name}")


def test_jsonl_round_trip_is_lossless(tmp_path: Path) -> None:
    path = _export(tmp_path, "jsonl")
    back = list(read_jsonl(path))
    assert [sc for sc, _ in back] == [scenario_a(), scenario_b()]
    assert [summary for _, summary in back] == [SUMMARY_A, SUMMARY_B]
    assert back[1][1]["ttr_true"] == math.inf
    assert read_jsonl_manifest(path) == manifest()


def test_jsonl_writes_numpy_scalars_as_plain_numbers(tmp_path: Path) -> None:
    summary = {"risk_peak": np.float64(0.25), "n_hits": np.int64(3), "flag": np.bool_(True)}
    path = export_catalogue("jsonl", [(scenario_a(), summary)], {}, tmp_path / "c.jsonl")
    [(_, back)] = list(read_jsonl(path))
    assert back == {"risk_peak": 0.25, "n_hits": 3, "flag": True}
    assert [type(v) for v in back.values()] == [float, int, bool]


def test_jsonl_is_strict_json_one_record_per_line(tmp_path: Path) -> None:
    lines = _export(tmp_path, "jsonl").read_text(encoding="utf-8").splitlines()
    assert len(lines) == 3
    records = [json.loads(line, parse_constant=_reject_constant) for line in lines]
    assert records[0]["kind"] == "manifest"
    assert records[0]["manifest"]["seed"] == 42
    assert [r["kind"] for r in records[1:]] == ["scenario", "scenario"]
    assert [r["index"] for r in records[1:]] == [0, 1]
    assert records[2]["summary"]["ttr_true"] == "Infinity"
    assert records[1]["scenario"] == scenario_a().to_dict()


@settings(max_examples=25, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=8).filter(
                           lambda k: k not in {"index", "file", *EXPECTED_COLUMNS}),
                       st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False),
                                 st.integers(-(2**53), 2**53),
                                 st.text(max_size=10).filter(
                                     lambda s: s not in ("Infinity", "-Infinity", "NaN"))),
                       max_size=6))
def test_jsonl_round_trips_any_flat_summary(summary: dict[str, Any]) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = export_catalogue("jsonl", [(scenario_a(), summary)], {"k": 1},
                               Path(tmp) / "c.jsonl")
        [(sc, back)] = list(read_jsonl(out))
    assert sc == scenario_a()
    assert back == summary
    assert [type(v) for v in back.values()] == [type(v) for v in summary.values()]


# --------------------------------------------------------------------------- csv


def test_csv_has_one_row_per_scenario_with_every_column(tmp_path: Path) -> None:
    text = _export(tmp_path, "csv").read_text(encoding="utf-8")
    rows = list(csv.reader(io.StringIO(text)))
    assert rows[0] == ["index", *EXPECTED_COLUMNS]
    assert len(rows) == 3
    a = dict(zip(rows[0], rows[1], strict=True))
    b = dict(zip(rows[0], rows[2], strict=True))
    assert a["index"] == "0" and b["index"] == "1"
    assert a["scenario_id"] == "a" and a["seed"] == "7"
    assert a["gap"] == "12.0" and a["dv"] == "4.0" and a["ttc"] == "3.0"
    assert a["p_y1"] == "-0.05" and a["p_a2"] == "0.25"
    assert a["n_steps"] == "4" and a["n_objects"] == "1"
    assert a["risk_peak"] == "0.4" and a["alarm_time"] == "0.625"
    assert a["ttr_manoeuvre"] == "brake" and a["class"] == "preventable"
    assert a["none_collision"] == "True" and a["r157_cc_collision"] == "False"
    assert a["exposure_weight"] == "0.01" and a["error"] == ""
    assert b["ttc"] == "inf" and b["ttr_true"] == "inf"
    assert b["ttr_manoeuvre"] == "" and b["r157_cc_t_brake"] == ""  # None
    assert float(a["duration"]) == pytest.approx(0.3)
    assert "\r" not in text


def test_csv_reads_back_with_pandas(tmp_path: Path) -> None:
    import pandas as pd

    df = pd.read_csv(_export(tmp_path, "csv"))
    assert list(df.columns) == ["index", *EXPECTED_COLUMNS]
    assert df.loc[0, "gap"] == 12.0
    assert df.loc[1, "ttc"] == math.inf


def test_csv_rejects_a_summary_key_that_the_first_row_did_not_have(tmp_path: Path) -> None:
    data = [(scenario_a(), dict(SUMMARY_A)), (scenario_b(), {**SUMMARY_B, "surprise": 1.0})]
    with pytest.raises(ExportError, match=r"item 1: column\(s\) 'surprise' not in the first row"):
        _export(tmp_path, "csv", data=data)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- parquet


def test_parquet_has_typed_columns_values_and_the_manifest(tmp_path: Path) -> None:
    path = _export(tmp_path, "parquet")
    table = pq.read_table(path)
    assert table.column_names == ["index", *EXPECTED_COLUMNS]
    assert table.schema.field("index").type == pa.int64()
    assert table.schema.field("seed").type == pa.int64()
    assert table.schema.field("gap").type == pa.float64()
    assert table.schema.field("ttr_manoeuvre").type == pa.string()
    assert table.schema.field("class").type == pa.string()
    assert table.schema.field("error").type == pa.string()  # empty in every row: still text
    assert table.schema.field("none_collision").type == pa.bool_()
    assert table.schema.field("r157_cc_t_brake").type == pa.float64()
    assert table.schema.field("ttr_true").type == pa.float64()
    assert table.schema.field("scenario_id").type == pa.string()
    rows = table.to_pylist()
    _assert_close_row({k: v for k, v in rows[0].items() if k != "index"}, ROW_A)
    _assert_close_row({k: v for k, v in rows[1].items() if k != "index"}, ROW_B)
    assert [r["index"] for r in rows] == [0, 1]
    meta = pq.read_schema(path).metadata
    assert json.loads(meta[b"scengen.manifest"]) == manifest()


def test_parquet_is_written_in_row_groups(tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tabular, "ROW_GROUP_SIZE", 2)
    data = [(scenario_a(), dict(SUMMARY_A))] * 5
    path = _export(tmp_path, "parquet", data=data)
    meta = pq.ParquetFile(path).metadata
    assert meta.num_row_groups == 3
    assert meta.num_rows == 5
    assert pq.read_table(path).column("index").to_pylist() == [0, 1, 2, 3, 4]


def test_parquet_rejects_a_column_that_changes_kind(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tabular, "ROW_GROUP_SIZE", 1)
    data = [(scenario_a(), {"note": 1.5}), (scenario_b(), {"note": "text"})]
    with pytest.raises(ExportError, match="item 1: column 'note' holds number values"):
        _export(tmp_path, "parquet", data=data)


# --------------------------------------------------------------------------- xosc


def _xsd(name: str) -> etree.XMLSchema:
    files = importlib.metadata.files("scenariogeneration") or []
    [path] = [f for f in files if f.name == name]
    return etree.XMLSchema(etree.parse(str(path.locate())))


@pytest.fixture(scope="module")
def xosc_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _export(tmp_path_factory.mktemp("xosc"), "xosc")


LOGICAL_FILES = ["catalogs/scengen_cutter_trajectories.xosc", "catalogue.csv",
                 "cutin_distribution.xosc", "cutin_logical.xosc", "cutin_weights.csv"]


@pytest.fixture(scope="module")
def xosc_replay_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("xosc_replay") / "catalogue.zip"
    return export_catalogue("xosc", items(), manifest(), out, mode="replay")


def test_xosc_zip_layout(xosc_zip: Path) -> None:
    with zipfile.ZipFile(xosc_zip) as zf:
        names = zf.namelist()
        infos = zf.infolist()
    assert names == [*LOGICAL_FILES, "manifest.json", "road.xodr",
                     "scenario_0000000.xosc", "scenario_0000001.xosc"]
    assert all(i.date_time == (1980, 1, 1, 0, 0, 0) for i in infos)


def test_every_xosc_validates_against_openscenario_1_2(xosc_zip: Path,
                                                       xosc_replay_zip: Path) -> None:
    schema = _xsd("OpenSCENARIO_1_2.xsd")
    for path in (xosc_zip, xosc_replay_zip):
        with zipfile.ZipFile(path) as zf:
            for name in [n for n in zf.namelist() if n.endswith(".xosc")]:
                doc = etree.fromstring(zf.read(name))
                assert schema.validate(doc), (name, schema.error_log)
                header = doc.find("FileHeader")
                assert header is not None
                assert (header.get("revMajor"), header.get("revMinor")) == ("1", "2")


def test_road_validates_against_opendrive_1_7_and_centres_the_ego_lane(xosc_zip: Path) -> None:
    with zipfile.ZipFile(xosc_zip) as zf:
        doc = etree.fromstring(zf.read("road.xodr"))
    schema = _xsd("opendrive_17_core.xsd")
    assert schema.validate(doc), schema.error_log
    geometry = doc.find("road/planView/geometry")
    assert geometry is not None
    # vehicles reach y = 3.75 (one lane left) and y = -3.5 (one lane right): 3 lanes of
    # 3.75 m, the reference line (left edge) 1.5 lane widths above the ego lane centre.
    assert float(geometry.get("y", "nan")) == 5.625
    assert float(geometry.get("hdg", "nan")) == 0.0
    lanes = doc.findall("road/lanes/laneSection/right/lane")
    assert [lane.get("id") for lane in lanes] == ["-1", "-2", "-3"]
    assert all(lane.find("width").get("a") == "3.75" for lane in lanes)  # type: ignore[union-attr]
    assert doc.findall("road/lanes/laneSection/left/lane") == []
    # x: from the rearmost vehicle end (-2.25 m) to the foremost (144.125 m) +- 50 m
    x0 = float(geometry.get("x", "nan"))
    length = float(geometry.get("length", "nan"))
    assert x0 <= -52.25 and x0 + length >= 194.125
    assert doc.find("header").get("date") is None  # type: ignore[union-attr]


def _vertices(doc: etree._Element, entity: str) -> list[etree._Element]:
    group = doc.xpath(f"//ManeuverGroup[Actors/EntityRef/@entityRef='{entity}']")
    assert len(group) == 1
    return list(group[0].iterfind(".//Trajectory/Shape/Polyline/Vertex"))


def _vertex(vertex: etree._Element) -> tuple[float, ...]:
    pos = vertex.find("Position/WorldPosition")
    assert pos is not None
    return (float(vertex.get("time", "nan")), float(pos.get("x", "nan")),
            float(pos.get("y", "nan")), float(pos.get("h", "nan")))


def test_xosc_replay_trajectories_are_the_rear_axles_of_the_scenario_tracks(
        xosc_replay_zip: Path) -> None:
    # positions are rear axles, 0.3 length behind the box centre along the heading:
    # cos 0.1 = 0.99500416527803, sin 0.1 = 0.09983341664683 (cut-in of a, 1.2 m back);
    # cos 0.2 = 0.98006657784124, sin 0.2 = 0.19866933079506 (car 1, 1.275 m back);
    # cos 0.125 = 0.99219766722933, sin 0.125 = 0.12467473338523
    with zipfile.ZipFile(xosc_replay_zip) as zf:
        doc_a = etree.fromstring(zf.read("scenario_0000000.xosc"))
        doc_b = etree.fromstring(zf.read("scenario_0000001.xosc"))
    for doc, expected in (
        (doc_a, {"ego": [(0.0, -1.35, 0.0, 0.0), (0.3, 7.65, 0.0, 0.0)],
                 "cutin": [(0.0, 18.80599500166636, 3.86980009997619, -0.1),
                           (0.3, 26.30599500166636, 3.11980009997619, -0.1)]}),
        # b's grid starts at t = 2 s: simulation time 0 is its first step
        (doc_b, {"ego": [(0.0, 98.5, 0.0, 0.0), (1.0, 128.5, 0.0, 0.0)],
                 "car 1": [(0.0, 108.75041511325242, -3.75330339676370, 0.2),
                           (1.0, 140.73494797428260, -1.65896028506617, 0.125)]}),
    ):
        n_steps = 4 if doc is doc_a else 3
        for entity, (first, last) in expected.items():
            vertices = _vertices(doc, entity)
            assert len(vertices) == n_steps
            assert _vertex(vertices[0]) == pytest.approx(first, abs=1e-12)
            assert _vertex(vertices[-1]) == pytest.approx(last, abs=1e-12)
    # a middle vertex too: the cut-in of scenario a at t = 0.2 s, centre (25, 3.25)
    middle = _vertices(doc_a, "cutin")[2]
    assert _vertex(middle) == pytest.approx((0.2, 23.80599500166636, 3.36980009997619, -0.1),
                                            abs=1e-12)


def test_xosc_replay_timing_entities_and_init(xosc_replay_zip: Path) -> None:
    with zipfile.ZipFile(xosc_replay_zip) as zf:
        doc = etree.fromstring(zf.read("scenario_0000001.xosc"))
    timings = doc.findall(".//FollowTrajectoryAction/TimeReference/Timing")
    assert len(timings) == 2
    for timing in timings:
        assert timing.get("domainAbsoluteRelative") == "absolute"
        assert float(timing.get("offset", "nan")) == 0.0
        assert float(timing.get("scale", "nan")) == 1.0
    [t0] = doc.xpath("/OpenSCENARIO/FileHeader/Properties/Property[@name='scengen.t0']/@value")
    assert t0 == "2.0"
    times = [float(v) for v in doc.xpath(
        "//ManeuverGroup[Actors/EntityRef/@entityRef='car 1']//Vertex/@time")]
    assert times == [0.0, 0.5, 1.0]
    modes = doc.xpath("//FollowTrajectoryAction/TrajectoryFollowingMode/@followingMode")
    assert modes == ["position", "position"]
    [car] = doc.xpath("//ScenarioObject[@name='car 1']/Vehicle")
    # reference point = rear axle: the box centre 0.3 * 4.25 m ahead, front axle 0.6 * 4.25
    assert car.find("BoundingBox/Center").get("x") == "1.275"
    assert car.find("Axles/RearAxle").get("positionX") == "0.0"
    assert float(car.find("Axles/FrontAxle").get("positionX")) == pytest.approx(2.55)
    assert car.xpath("Properties/Property[@name='plineInterpolation']/@value") == ["segment"]
    assert doc.xpath("//Property[@name='type']") == []  # replay: nobody is the ego vehicle
    dims = car.find("BoundingBox/Dimensions")
    assert (dims.get("length"), dims.get("width")) == ("4.25", "1.75")
    [teleport] = doc.xpath("//Init//Private[@entityRef='car 1']//TeleportAction//WorldPosition")
    assert (float(teleport.get("x")), float(teleport.get("y")), float(teleport.get("h"))) == \
        pytest.approx((108.75041511325242, -3.75330339676370, 0.2), abs=1e-12)
    [speed] = doc.xpath("//Init//Private[@entityRef='car 1']//AbsoluteTargetSpeed/@value")
    assert float(speed) == 32.0
    [stop] = doc.xpath("/OpenSCENARIO/Storyboard/StopTrigger//SimulationTimeCondition/@value")
    assert float(stop) == 1.0  # 3 s - 2 s
    [collision] = doc.xpath("/OpenSCENARIO/Storyboard/StopTrigger//CollisionCondition")
    assert collision.xpath("EntityRef/@entityRef") == ["car 1"]
    assert collision.xpath("../../TriggeringEntities/EntityRef/@entityRef") == ["ego"]
    assert doc.xpath("//RoadNetwork/LogicFile/@filepath") == ["road.xodr"]


def scenario_c() -> ConcreteScenario:
    """Both cars straight at constant speed up to step 2, then the cutter turns right."""
    return ConcreteScenario(
        t=np.array([0.0, 0.1, 0.2, 0.3, 0.4]),
        ego=_track("ego", 4.0, 1.8, [0.0, 3.0, 6.0, 9.0, 12.0], [0.0] * 5, [0.0] * 5,
                   [30.0] * 5),
        objects=(_track("cutter", 4.0, 1.8, [20.0, 22.5, 25.0, 27.6, 30.4],
                        [3.5, 3.5, 3.5, 3.4, 3.2], [0.0, 0.0, 0.0, -0.1, -0.1],
                        [25.0, 25.0, 25.0, 26.0, 27.0]),),
        params=dict(PARAMS_A),
    )


def _condition_groups(doc: etree._Element) -> list[list[tuple[str, ...]]]:
    """The storyboard's stop trigger as groups of (condition kind, its key attributes)."""
    out = []
    for group in doc.xpath("/OpenSCENARIO/Storyboard/StopTrigger/ConditionGroup"):
        conds = []
        for cond in group.iterfind("Condition"):
            [leaf] = cond.xpath("ByValueCondition/* | ByEntityCondition/EntityCondition/*")
            who = cond.xpath("ByEntityCondition/TriggeringEntities/EntityRef/@entityRef")
            keys = ("entityRef", "rule", "value", "freespace", "relativeDistanceType",
                    "coordinateSystem", "storyboardElementRef", "state")
            attrs = dict(leaf.attrib)
            attrs.update(("entityRef", r) for r in leaf.xpath(".//EntityRef/@entityRef"))
            conds.append((etree.QName(leaf).localname, *who,
                          *(f"{k}={attrs[k]}" for k in keys if k in attrs)))
        out.append(conds)
    return out


def test_xosc_test_mode_ego_is_the_system_under_test_and_the_cutter_ignores_it(
        tmp_path: Path) -> None:
    path = _export(tmp_path, "xosc", data=[(scenario_c(), {"exposure_weight": 0.5})])
    with zipfile.ZipFile(path) as zf:
        doc = etree.fromstring(zf.read("scenario_0000000.xosc"))
    assert doc.xpath("//ScenarioObject[@name='ego']/Vehicle/Properties/Property"
                     "[@name='type']/@value") == ["ego_vehicle"]
    assert doc.xpath("//ManeuverGroup[Actors/EntityRef/@entityRef='ego']") == []
    [teleport] = doc.xpath("//Init//Private[@entityRef='ego']//TeleportAction//WorldPosition")
    assert (teleport.get("x"), teleport.get("y")) == ("-1.2", "0.0")
    [timing] = doc.xpath("//FollowTrajectoryAction/TimeReference/Timing")
    assert timing.get("domainAbsoluteRelative") == "relative"
    # the cutter follows its whole trajectory from simulation time 0, relative to where it
    # starts (rear axle (18.8, 3.5)): no condition on the ego starts it
    assert doc.xpath("//Event/StartTrigger//ByEntityCondition") == []
    assert doc.xpath("//Event/StartTrigger//SimulationTimeCondition/@value") == ["0.0"]
    vertices = _vertices(doc, "cutter")
    assert [float(v.get("time")) for v in vertices] == pytest.approx(
        [0.0, 0.1, 0.2, 0.3, 0.4, 30.4])
    rel = [v.find("Position/RelativeWorldPosition") for v in vertices]
    assert all(r is not None and r.get("entityRef") == "cutter" for r in rel)
    # step 3: rear axle (27.6 - 1.2 cos 0.1, 3.4 + 1.2 sin 0.1) minus step 0's (18.8, 3.5)
    assert (float(rel[3].get("dx")), float(rel[3].get("dy"))) == pytest.approx(
        (7.60599500166636, 0.01980009997619), abs=1e-12)
    assert float(rel[3].find("Orientation").get("h")) == -0.1
    # after the scenario's end (0.4 s) it keeps its last speed, 27 m/s, along its lane up
    # to the time limit 30.4 s: step 4's rear axle (29.20599500166636, 3.31980009997619)
    # plus 27 * 30 = 810 m in x
    assert (float(rel[5].get("dx")), float(rel[5].get("dy"))) == pytest.approx(
        (820.40599500166636, -0.18019990002381), abs=1e-9)
    assert float(rel[5].find("Orientation").get("h")) == 0.0
    # stop: a collision; from 0.4 s on, the ego not faster than the cutter, or closing
    # with contact beyond 60 s, or the cutter beside its path, or the ego ahead of the
    # cutter (the cutter's headway to the ego > 0) and not slower; at the latest at 30.4 s
    later = ("SimulationTimeCondition", "rule=greaterOrEqual", "value=0.4")
    assert _condition_groups(doc) == [
        [("CollisionCondition", "ego", "entityRef=cutter")],
        [later, ("RelativeSpeedCondition", "ego", "entityRef=cutter", "rule=lessOrEqual",
                 "value=0.0")],
        [later, ("TimeToCollisionCondition", "ego", "entityRef=cutter", "rule=greaterThan",
                 "value=60.0", "freespace=true", "relativeDistanceType=longitudinal",
                 "coordinateSystem=entity")],
        [later, ("RelativeDistanceCondition", "ego", "entityRef=cutter", "rule=greaterThan",
                 "value=0.0", "freespace=true", "relativeDistanceType=lateral",
                 "coordinateSystem=entity")],
        [later, ("RelativeSpeedCondition", "ego", "entityRef=cutter", "rule=greaterOrEqual",
                 "value=0.0"),
         ("TimeHeadwayCondition", "cutter", "entityRef=ego", "rule=greaterThan", "value=0.0",
          "freespace=true", "relativeDistanceType=longitudinal", "coordinateSystem=entity")],
        [("SimulationTimeCondition", "rule=greaterOrEqual", "value=30.4")],
    ]


def test_xosc_replay_keeps_its_stop_trigger(xosc_replay_zip: Path) -> None:
    with zipfile.ZipFile(xosc_replay_zip) as zf:
        doc = etree.fromstring(zf.read("scenario_0000000.xosc"))
    assert _condition_groups(doc) == [
        [("CollisionCondition", "ego", "entityRef=cutin")],
        [("StoryboardElementStateCondition", "storyboardElementRef=cutin manoeuvre",
          "state=completeState")],
        [("SimulationTimeCondition", "rule=greaterOrEqual", "value=0.3")],
    ]


def test_xosc_test_mode_road_reaches_as_far_as_any_vehicle_can_drive(
        xosc_zip: Path, xosc_replay_zip: Path) -> None:
    # time limits: a 0.3 s + 30 s, b 1 s + 30 s; at 70 m/s from their starts the farthest
    # box end is b's "car 1": 110 + 70 * 31 + 4.25 / 2 = 2282.125 m, the road 50 m more;
    # behind: the rearmost box end -2.25 m, 50 m more
    ranges = {}
    for mode, path in (("test", xosc_zip), ("replay", xosc_replay_zip)):
        with zipfile.ZipFile(path) as zf:
            doc = etree.fromstring(zf.read("road.xodr"))
            ranges[mode] = json.loads(zf.read("manifest.json"))["export"]["road_x_range"]
        geometry = doc.find("road/planView/geometry")
        x0, length = float(geometry.get("x", "nan")), float(geometry.get("length", "nan"))
        assert [x0, x0 + length] == ranges[mode]
    assert ranges == {"test": [-53.0, 2333.0], "replay": [-53.0, 195.0]}


def test_xosc_declares_the_cut_in_parameters_and_ttc_with_units(xosc_zip: Path) -> None:
    with zipfile.ZipFile(xosc_zip) as zf:
        doc = etree.fromstring(zf.read("scenario_0000001.xosc"))
    decls = doc.find("ParameterDeclarations")
    assert decls is not None
    names = [d.get("name") for d in decls.iterfind("ParameterDeclaration")]
    assert names[:9] == ["p_y1", "p_t", "p_a1", "p_a2", "p_a3", "p_v0", "dv", "gap", "ttc"]
    values = {d.get("name"): d.get("value") for d in decls.iterfind("ParameterDeclaration")}
    assert (values["p_y1"], values["gap"], values["ttc"]) == ("0.04", "20.0", "INF")
    comments = [c.text for c in decls if isinstance(c, etree._Comment)]
    assert comments[0].startswith(" p_y1 [rad/s]: yaw-rate amplitude")
    assert comments[8].startswith(" ttc [s]:")


def test_xosc_logical_scenario_has_one_value_set_per_scenario(xosc_zip: Path) -> None:
    with zipfile.ZipFile(xosc_zip) as zf:
        logical = etree.fromstring(zf.read("cutin_logical.xosc"))
        dist = etree.fromstring(zf.read("cutin_distribution.xosc"))
        catalog = etree.fromstring(zf.read("catalogs/scengen_cutter_trajectories.xosc"))
        weights = list(csv.DictReader(io.StringIO(zf.read("cutin_weights.csv").decode())))
    declared = logical.xpath("/OpenSCENARIO/ParameterDeclarations/ParameterDeclaration/@name")
    sets = dist.findall(".//ValueSetDistribution/ParameterValueSet")
    assert len(sets) == 2
    for value_set in sets:
        assert value_set.xpath("ParameterAssignment/@parameterRef") == declared
    assert dist.xpath("//ScenarioFile/@filepath") == ["cutin_logical.xosc"]
    gaps = [s.xpath("ParameterAssignment[@parameterRef='gap']/@value")[0] for s in sets]
    assert gaps == ["12.0", "20.0"]
    entries = [s.xpath("ParameterAssignment[@parameterRef='cutter_trajectory']/@value")[0]
               for s in sets]
    assert entries == ["scenario_0000000", "scenario_0000001"]
    assert catalog.xpath("/OpenSCENARIO/Catalog/Trajectory/@name") == entries
    assert logical.xpath("//FollowTrajectoryAction/TrajectoryRef/CatalogReference/@entryName") \
        == ["$cutter_trajectory"]
    assert [(w["permutation"], w["index"], w["file"], w["exposure_weight"]) for w in weights] \
        == [("0", "0", "scenario_0000000.xosc", "0.01"), ("1", "1", "scenario_0000001.xosc", "2.0")]


def test_xosc_without_a_logical_scenario_says_why(tmp_path: Path) -> None:
    sc = scenario_a()
    bare = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects)  # no parameters
    path = _export(tmp_path, "xosc", data=[(bare, {})])
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        m = json.loads(zf.read("manifest.json"))
    assert "cutin_logical.xosc" not in names and "cutin_distribution.xosc" not in names
    assert m["export"]["logical_scenario"] == {
        "included": False, "reason": "item 0 lacks the parameter(s) p_y1, p_t, p_a1, p_a2, "
        "p_a3, p_v0, dv, gap"}


@pytest.mark.parametrize(("fmt", "mode", "message"), [
    ("xosc", "bogus", "mode: unknown OpenSCENARIO mode 'bogus'; choose one of test, replay"),
    ("csv", "test", "mode: only the xosc export has modes, not 'csv'"),
])
def test_bad_mode_is_named(tmp_path: Path, fmt: str, mode: str, message: str) -> None:
    with pytest.raises(ExportError, match=re.escape(message)):
        export_catalogue(fmt, items(), manifest(), tmp_path / "out", mode=mode)
    assert list(tmp_path.iterdir()) == []


def test_xosc_manifest_and_index(xosc_zip: Path) -> None:
    with zipfile.ZipFile(xosc_zip) as zf:
        m = json.loads(zf.read("manifest.json"), parse_constant=_reject_constant)
        index = list(csv.DictReader(io.StringIO(zf.read("catalogue.csv").decode())))
    expected = manifest()
    for key, value in expected.items():
        assert m[key] == value, key
    assert m["export"]["n_scenarios"] == 2
    assert m["export"]["lane_width"] == 3.75
    assert m["export"]["road_file"] == "road.xodr"
    assert [r["file"] for r in index] == ["scenario_0000000.xosc", "scenario_0000001.xosc"]
    assert [r["scenario_id"] for r in index] == ["a", "b"]
    assert index[0]["risk_peak"] == "0.4"


def test_xosc_road_grows_lanes_for_far_vehicles_and_uses_the_lane_width(
        tmp_path: Path) -> None:
    sc = scenario_a()
    far = _track("far", 4.0, 1.8, [0.0, 1.0, 2.0, 3.0], [7.0] * 4, [0.0] * 4, [10.0] * 4)
    wide = ConcreteScenario(t=sc.t, ego=sc.ego, objects=(*sc.objects, far),
                            params={**PARAMS_A, "lane_width": 3.5})
    path = _export(tmp_path, "xosc", data=[(wide, {})])
    with zipfile.ZipFile(path) as zf:
        doc = etree.fromstring(zf.read("road.xodr"))
    lanes = doc.findall("road/lanes/laneSection/right/lane")
    # y = 7 m is two 3.5 m lanes left of the ego lane: lanes -1 (far), -2, -3 (ego), -4
    assert [lane.get("id") for lane in lanes] == ["-1", "-2", "-3", "-4"]
    assert float(doc.find("road/planView/geometry").get("y")) == 8.75  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("provenance", "expected_y"),
    [({"lane_width": 3.5}, "5.25"), ({}, "5.625"), ({"lane_width": 4}, "6.0")],
)
def test_xosc_lane_width_from_provenance_or_default(tmp_path: Path, provenance: dict[str, Any],
                                                    expected_y: str) -> None:
    sc = scenario_a()
    built = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects, params=PARAMS_A,
                             provenance=provenance)
    path = _export(tmp_path, "xosc", data=[(built, {})])
    with zipfile.ZipFile(path) as zf:
        doc = etree.fromstring(zf.read("road.xodr"))
    # reference line 1.5 lane widths left of the ego lane centre
    assert doc.find("road/planView/geometry").get("y") == expected_y  # type: ignore[union-attr]


def test_xosc_rejects_a_bad_lane_width(tmp_path: Path) -> None:
    sc = scenario_a()
    bad = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects,
                           provenance={"lane_width": "wide"})
    message = "item 0: provenance.lane_width must be a number > 0 m, got 'wide'"
    with pytest.raises(ExportError, match=re.escape(message)):
        _export(tmp_path, "xosc", data=[(bad, {})])


def test_xosc_rejects_mixed_lane_widths(tmp_path: Path) -> None:
    sc = scenario_a()
    other = ConcreteScenario(t=sc.t, ego=sc.ego, objects=sc.objects,
                             params={**PARAMS_A, "lane_width": 3.5})
    with pytest.raises(ExportError, match=re.escape("item 1: lane_width 3.5 m differs")):
        _export(tmp_path, "xosc", data=[(sc, {}), (other, {})])
    assert list(tmp_path.iterdir()) == []


def test_schema_failure_is_a_clear_error() -> None:
    import xml.etree.ElementTree as ET

    from app.exports._xosc import _validated_bytes

    message = "does not validate against OpenSCENARIO_1_2.xsd"
    with pytest.raises(ExportError, match=re.escape(message)):
        _validated_bytes(ET.Element("OpenSCENARIO"), "OpenSCENARIO_1_2.xsd", "scenario 0")


# --------------------------------------------------------------------------- determinism


@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_same_input_gives_byte_identical_files(tmp_path: Path, fmt: str) -> None:
    first = _export(tmp_path, fmt, name="one")
    second = _export(tmp_path, fmt, name="two")
    assert first.read_bytes() == second.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one", "two"]  # no leftovers


def test_concurrent_xosc_exports_in_threads_agree(tmp_path: Path) -> None:
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        paths = list(pool.map(lambda name: _export(tmp_path, "xosc", name=name),
                              ["one", "two", "three", "four"]))
    contents = {p.read_bytes() for p in paths}
    assert len(contents) == 1


def test_different_input_gives_different_files(tmp_path: Path) -> None:
    first = _export(tmp_path, "xosc", name="one")
    second = _export(tmp_path, "xosc", name="two", data=[items()[1], items()[0]])
    assert first.read_bytes() != second.read_bytes()


# --------------------------------------------------------------------------- streaming and errors


@pytest.mark.slow
@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_items_are_consumed_lazily_from_a_generator(tmp_path: Path, fmt: str) -> None:
    # Every item is a fresh scenario object. When item i is asked for, item i - 2 must be
    # gone already: an exporter that first collected the whole stream (list(items)) would
    # still hold it, so this fails for a non-streaming exporter.
    consumed: list[int] = []
    refs: list[weakref.ref[ConcreteScenario]] = []
    still_alive: list[int] = []

    def gen() -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
        for i, (scenario, summary) in enumerate(items() * 3):
            gc.collect()
            if i >= 2 and refs[i - 2]() is not None:
                still_alive.append(i - 2)
            fresh = ConcreteScenario.from_dict(scenario.to_dict())
            refs.append(weakref.ref(fresh))
            consumed.append(i)
            yield fresh, dict(summary)

    export_catalogue(fmt, gen(), {}, tmp_path / "out")
    assert consumed == [0, 1, 2, 3, 4, 5]
    assert still_alive == []


@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_a_failing_stream_leaves_no_file(tmp_path: Path, fmt: str) -> None:
    def gen() -> Iterator[tuple[ConcreteScenario, dict[str, Any]]]:
        yield items()[0]
        raise RuntimeError("database went away")

    with pytest.raises(RuntimeError, match="database went away"):
        export_catalogue(fmt, gen(), {}, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_unknown_format_is_named(tmp_path: Path) -> None:
    message = "unknown export format 'xlsx'; choose one of jsonl, csv, parquet, xosc"
    with pytest.raises(ExportError, match=re.escape(message)):
        export_catalogue("xlsx", items(), {}, tmp_path / "out")


@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_empty_catalogue_is_an_error(tmp_path: Path, fmt: str) -> None:
    with pytest.raises(ExportError, match="the catalogue is empty"):
        export_catalogue(fmt, [], {}, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_scenario_without_objects_is_an_error(tmp_path: Path, fmt: str) -> None:
    sc = scenario_a()
    alone = ConcreteScenario(t=sc.t, ego=sc.ego, objects=())
    with pytest.raises(ExportError, match="item 1: the scenario has no objects besides the ego"):
        export_catalogue(fmt, [items()[0], (alone, {})], {}, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ([("not a scenario", {})], "item 0: expected a ConcreteScenario, got str"),
        ([(None,)], r"item 0: expected a \(scenario, summary\) pair"),
        ([(None, {}, 3)], r"item 0: expected a \(scenario, summary\) pair"),
        (42, "items: expected an iterable"),
        ({"a": 1}, "items: expected an iterable"),
    ],
)
def test_bad_items_are_named(tmp_path: Path, data: Any, message: str) -> None:
    with pytest.raises(ExportError, match=message):
        export_catalogue("csv", data, {}, tmp_path / "out")


def test_bad_manifest_and_output_path(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="manifest: expected a mapping"):
        export_catalogue("csv", items(), [], tmp_path / "out")  # type: ignore[arg-type]
    with pytest.raises(ExportError, match=re.escape("manifest.when: expected JSON-able data")):
        export_catalogue("csv", items(), {"when": object()}, tmp_path / "out")
    with pytest.raises(ExportError, match="does not exist"):
        export_catalogue("csv", items(), {}, tmp_path / "missing" / "out")
    with pytest.raises(ExportError, match="is a directory"):
        export_catalogue("csv", items(), {}, tmp_path)
    with pytest.raises(ExportError, match="'export' is reserved"):
        export_catalogue("xosc", items(), {"export": 1}, tmp_path / "out")
    with pytest.raises(ExportError, match="created_at: 'yesterday' is not an ISO 8601"):
        export_catalogue("xosc", items(), {"created_at": "yesterday"}, tmp_path / "out")


def test_xosc_header_date_comes_from_created_at(tmp_path: Path) -> None:
    path = export_catalogue("xosc", items(), {"created_at": "2026-03-04T05:06:07"},
                            tmp_path / "c.zip")
    with zipfile.ZipFile(path) as zf:
        doc = etree.fromstring(zf.read("scenario_0000000.xosc"))
    assert doc.find("FileHeader").get("date") == "2026-03-04T05:06:07"  # type: ignore[union-attr]


def test_xosc_declares_the_criticality_fields_present_in_the_row(tmp_path: Path) -> None:
    summary = {**SUMMARY_A, "t_p": 1.5, "class": "preventable", "none_collision": True,
               "r157_cc_t_brake": None, "ttr_true": math.inf}
    path = _export(tmp_path, "xosc", data=[(scenario_a(), summary)])
    with zipfile.ZipFile(path) as zf:
        doc = etree.fromstring(zf.read("scenario_0000000.xosc"))
        logical = etree.fromstring(zf.read("cutin_logical.xosc"))
    decls = {d.get("name"): (d.get("parameterType"), d.get("value"))
             for d in doc.iterfind("ParameterDeclarations/ParameterDeclaration")}
    assert decls["t_p"] == ("double", "1.5")
    assert decls["class"] == ("string", "preventable")
    assert decls["none_collision"] == ("boolean", "true")
    assert decls["ttr_true"] == ("double", "INF")
    assert "r157_cc_t_brake" not in decls  # null: skipped
    comments = [c.text for c in doc.find("ParameterDeclarations")
                if isinstance(c, etree._Comment)]
    assert any(c.startswith(" t_p [s]: perception moment") for c in comments)
    # the logical scenario declares what the row holds; a null number is NaN there
    ldecls = {d.get("name"): (d.get("parameterType"), d.get("value"))
              for d in logical.iterfind("ParameterDeclarations/ParameterDeclaration")}
    assert ldecls["r157_cc_t_brake"] == ("double", "NaN")
    assert ldecls["none_collision"] == ("string", "true")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(min_value=0.0, max_value=0.5), min_size=2, max_size=60))
def test_thinned_vertices_are_spaced_for_esmini_and_keep_both_ends(steps: list[float]) -> None:
    from app.exports._osc import MIN_VERTEX_SPACING, thinned

    x = np.concatenate([[0.0], np.cumsum(steps)])
    y = 0.5 * x
    keep = thinned(x, y)
    assert keep[0] == 0 and keep[-1] == x.shape[0] - 1
    assert np.all(np.diff(keep) > 0)
    gaps = np.hypot(np.diff(x[keep]), np.diff(y[keep]))
    assert np.all(gaps >= MIN_VERTEX_SPACING) or keep.tolist() == [0, x.shape[0] - 1]
    if np.all(np.hypot(np.diff(x), np.diff(y)) >= MIN_VERTEX_SPACING):
        assert keep.tolist() == list(range(x.shape[0]))  # nothing to thin: all kept


@pytest.mark.slow
def test_row_step_and_duration_carry_no_float_noise() -> None:
    # differences of grid times are noisy in floating point (10.6 - 10.5 is
    # 0.09999999999999964): the exported dt and duration read as the decimals they are
    from sampler import build_scenario
    from tests.sampler.factories import base_params

    sc = build_scenario(base_params())
    assert sc.dt != 0.1  # the median difference of the grid is noisy ...
    row = scenario_row(sc, {})
    assert repr(row["dt"]) == "0.1"  # ... the exported step is not
    assert row["duration"] == float(f"{row['duration']:.6f}")
    assert row["n_steps"] == round(row["duration"] / 0.1) + 1
