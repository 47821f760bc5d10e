"""Datasets: the embedded data first, show, paged parameter table (JSON/CSV), uploads with
a size limit; a bad or oversized upload stores nothing."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import pytest

from datasets.cutin_model import PARAM_NAMES
from datasets.embedded import default_parameter_table, load_default_events


def _ids(client: Any) -> list[str]:
    return [d["id"] for d in client.get("/datasets").json()["datasets"]]


def test_list_starts_with_the_embedded_real_data(client: Any) -> None:
    r = client.get("/datasets")
    assert r.status_code == 200
    first = r.json()["datasets"][0]
    assert first["id"] == "tno-cutin" and first["embedded"] is True
    assert first["n_cutins"] == len(default_parameter_table())
    assert client.get("/datasets/tno-cutin").json()["kind"] == "embedded"


def test_unknown_dataset_is_404(client: Any) -> None:
    for path in ("/datasets/nope", "/datasets/nope/parameters"):
        r = client.get(path)
        assert r.status_code == 404
        assert r.json()["error"]["field"] == "path.dataset_id"


def test_parameter_table_pages_as_json_and_csv(client: Any) -> None:
    table = default_parameter_table()
    r = client.get("/datasets/tno-cutin/parameters", params={"offset": 3, "limit": 4})
    assert r.status_code == 200
    body = r.json()
    assert body["total"] == len(table) and len(body["rows"]) == 4
    for name in PARAM_NAMES:
        assert body["rows"][0][name] == pytest.approx(float(table[name].iloc[3]), rel=1e-12)
    r = client.get("/datasets/tno-cutin/parameters",
                   params={"offset": 0, "limit": 5, "format": "csv"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert len(rows) == 5 and float(rows[2]["gap"]) == pytest.approx(table["gap"].iloc[2])
    assert r.headers["x-total-count"] == str(len(table))


@pytest.mark.parametrize(("params", "field"), [
    ({"limit": 0}, "query.limit"),
    ({"offset": -1}, "query.offset"),
    ({"format": "xml"}, "query.format"),
])
def test_bad_paging_is_422_naming_the_field(client: Any, params: dict[str, Any],
                                            field: str) -> None:
    r = client.get("/datasets/tno-cutin/parameters", params=params)
    assert r.status_code == 422 and r.json()["error"]["field"] == field


def _egocentric_csv(tmp_path: Path, n_events: int) -> Path:
    events = load_default_events()
    keep = events["event_id"].drop_duplicates().iloc[:n_events]
    path = tmp_path / "drives.csv"
    events[events["event_id"].isin(keep)].to_csv(path, index=False)
    return path


def test_upload_an_egocentric_file(client: Any, tmp_path: Path) -> None:
    path = _egocentric_csv(tmp_path, 12)
    with open(path, "rb") as fh:
        r = client.post("/datasets", data={"kind": "egocentric", "name": "my drives"},
                        files=[("files", ("drives.csv", fh, "text/csv"))])
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["name"] == "my drives" and body["kind"] == "egocentric"
    assert 0 < body["n_cutins"] <= 12
    assert body["n_cutins"] + body["report"]["n_skipped"] == 12
    ids = _ids(client)
    assert ids[0] == "tno-cutin" and body["id"] in ids
    page = client.get(f"/datasets/{body['id']}/parameters").json()
    assert page["total"] == body["n_cutins"]


def test_upload_a_highd_recording(client: Any, tmp_path: Path) -> None:
    from datasets.highd import write_highd
    from datasets.synth import generate_recording

    rec = generate_recording(3, minutes=1.0, vehicles=60, frame_rate=5.0).recording
    paths = write_highd(rec, tmp_path)
    handles = [open(p, "rb") for p in paths]  # noqa: SIM115 - closed below
    try:
        r = client.post("/datasets", data={"kind": "highd"},
                        files=[("files", (p.name, h, "text/csv"))
                               for p, h in zip(paths, handles, strict=True)])
    finally:
        for h in handles:
            h.close()
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["kind"] == "highd" and body["n_cutins"] > 0
    assert sorted(body["report"]["files"]) == sorted(p.name for p in paths)
    # issue 12: the exposure per vehicle, summed over the tracked vehicles (tracksMeta),
    # agrees with the recording's own totals (recordingMeta, rounded to 0.01)
    exp = body["exposure"]
    meta = rec.recording_meta.iloc[0]
    assert exp["n_events"] == body["n_cutins"]
    assert exp["hours"] * 3600 == pytest.approx(meta["totalDrivenTime"], abs=0.01)
    assert exp["km"] * 1000 == pytest.approx(meta["totalDrivenDistance"], abs=0.01)
    assert client.get(f"/datasets/{body['id']}").json()["exposure"] == exp


def test_a_model_fitted_on_a_highd_upload_gives_rates_per_km(client: Any,
                                                             tmp_path: Path) -> None:
    """The dataset's exposure is carried into a model fitted on it: P(A) then comes with
    cut-ins per hour and per 10^6 km (hand: n / vehicle-km * 1e6 * P(A))."""
    from datasets.highd import write_highd
    from datasets.synth import generate_recording

    # 12 cut-ins in 0.73 MB (the test client's upload limit is 1 MB)
    rec = generate_recording(7, minutes=3.0, vehicles=300, frame_rate=1.5).recording
    files = [("files", (path.name, path.read_bytes(), "text/csv"))
             for path in write_highd(rec, tmp_path)]
    up = client.post("/datasets", data={"kind": "highd"}, files=files)
    assert up.status_code == 201, up.text
    exp = up.json()["exposure"]
    assert exp["n_events"] >= 10
    fit = client.post("/models", json={"dataset": up.json()["id"], "options": {
        "features": ["gap", "dv"], "k_range": [1, 1], "n_init": 1, "cv_folds": 2,
        "n_report_samples": 500, "n_bootstrap": 0}})
    assert fit.status_code == 201, fit.text
    r = client.post("/scenarios", json={"model": fit.json()["id"], "n": 2, "seed": 1,
                                         "constraints": ["gap>5"], "score": False})
    assert r.status_code == 200, r.text
    p = r.json()["p_region"]
    assert p["rates"]["exposure"]["km"] == exp["km"]
    assert p["rates"]["per_1e6_km"]["estimate"] == pytest.approx(
        exp["n_events"] / exp["km"] * 1e6 * p["estimate"], rel=1e-12)
    assert p["rates"]["per_hour"]["estimate"] == pytest.approx(
        exp["n_events"] / exp["hours"] * p["estimate"], rel=1e-12)
    assert p["model_ci"] is None  # no bootstrap refits asked for


def test_the_embedded_dataset_has_the_tno_exposure(client: Any) -> None:
    body = client.get("/datasets/tno-cutin").json()
    assert body["exposure"]["hours"] == 63.0 and body["exposure"]["km"] is None


def test_bad_uploads_store_nothing(client: Any, tmp_path: Path) -> None:
    before = _ids(client)
    garbage = client.post("/datasets", data={"kind": "egocentric"},
                          files=[("files", ("x.csv", b"not,a\n1,ego-centric file\n", "text/csv"))])
    assert garbage.status_code == 422 and garbage.json()["error"]["field"] == "body.files"
    wrong_kind = client.post("/datasets", data={"kind": "video"},
                             files=[("files", ("x.csv", b"a", "text/csv"))])
    assert wrong_kind.status_code == 422 and wrong_kind.json()["error"]["field"] == "body.kind"
    no_file = client.post("/datasets", data={"kind": "egocentric"})
    assert no_file.status_code == 422 and no_file.json()["error"]["field"] == "body.files"
    bad_name = client.post("/datasets", data={"kind": "egocentric"},
                           files=[("files", ("../../etc/x;.csv", b"a", "text/csv"))])
    assert bad_name.status_code == 422
    big = b"x" * 1_200_000  # the test client's limit is 1,000,000 bytes
    too_large = client.post("/datasets", data={"kind": "egocentric"},
                            files=[("files", ("big.csv", big, "text/csv"))])
    assert too_large.status_code == 413
    assert too_large.json()["error"]["status"] == 413
    assert "1000000" in too_large.json()["error"]["message"]
    assert _ids(client) == before
    staging = Path(client.app.state.ctx.data_dir) / "tmp"
    assert not any(staging.glob("upload-*"))
