"""Issue 14 items 12 and 13: a compressed upload is limited by its decompressed size too;
data in the wrong units (km/h, mm) is refused with a clear message unless overridden."""

from __future__ import annotations

import gzip
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from datasets.embedded import load_default_events
from datasets.plausibility import implausible
from tests.app.factories import copy_model_cache, make_app, make_settings

EXPANDED_LIMIT = 2_000_000


@pytest.fixture(scope="module")
def guarded(model_cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from fastapi.testclient import TestClient

    data_dir = tmp_path_factory.mktemp("guarded")
    copy_model_cache(model_cache_dir, data_dir)
    app = make_app(make_settings(data_dir, upload_limit_bytes=1_000_000,
                                 upload_expanded_limit_bytes=EXPANDED_LIMIT))
    with TestClient(app) as client:
        yield client


def _events(n: int = 12) -> pd.DataFrame:
    events = load_default_events()
    keep = events["event_id"].drop_duplicates().iloc[:n]
    return events[events["event_id"].isin(keep)].copy()


def _post(client: Any, name: str, payload: bytes, **form: str) -> Any:
    return client.post("/datasets", data={"kind": "egocentric", **form},
                       files=[("files", (name, payload, "application/octet-stream"))])


def _ids(client: Any) -> list[str]:
    return [d["id"] for d in client.get("/datasets").json()["datasets"]]


# --------------------------------------------------------------------------- item 12
def test_a_gzip_bomb_is_413_naming_the_decompressed_limit(guarded: Any) -> None:
    header = ",".join(_events(1).columns) + "\n"
    row = ",".join(["e1"] + ["1.0"] * (len(_events(1).columns) - 1)) + "\n"
    body = (header + row * (3 * EXPANDED_LIMIT // len(row))).encode()
    bomb = gzip.compress(body)
    assert len(bomb) < 1_000_000 < EXPANDED_LIMIT < len(body)  # passes the plain limit
    before = _ids(guarded)
    r = _post(guarded, "drives.csv.gz", bomb)
    assert r.status_code == 413, r.text
    err = r.json()["error"]
    assert str(EXPANDED_LIMIT) in err["message"] and "decompressed" in err["message"]
    assert err["field"] == "body.files"
    assert _ids(guarded) == before


def test_a_small_gzip_upload_still_works(guarded: Any) -> None:
    buf = io.BytesIO()
    _events().to_csv(buf, index=False)
    r = _post(guarded, "drives.csv.gz", gzip.compress(buf.getvalue()))
    assert r.status_code == 201, r.text
    assert r.json()["report"]["plausibility_warnings"] == []


def test_a_broken_gzip_is_422(guarded: Any) -> None:
    r = _post(guarded, "drives.csv.gz", b"\x1f\x8b\x08\x00garbage")
    assert r.status_code == 422 and r.json()["error"]["field"] == "body.files"


# --------------------------------------------------------------------------- item 13
def _scaled(columns: list[str], factor: float) -> bytes:
    events = _events()
    for col in columns:
        if col in events:
            events[col] = events[col] * factor
    return events.to_csv(index=False).encode()


@pytest.mark.slow
@pytest.mark.parametrize(("columns", "factor", "words"), [
    (["ego_v", "target_v"], 3.6, ("v_ego", "km/h")),
    (["target_dx", "target_dy", "ego_length", "ego_width", "target_length", "target_width",
      "ego_y", "lane_width"], 1000.0, ("gap", "mm")),
])
def test_wrong_units_are_refused_unless_overridden(guarded: Any, columns: list[str],
                                                   factor: float, words: tuple[str, ...]) -> None:
    before = _ids(guarded)
    payload = _scaled(columns, factor)
    r = _post(guarded, "drives.csv", payload)
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["field"] == "body.files"
    assert all(w in err["message"] for w in words) and "allow_implausible" in err["message"]
    assert _ids(guarded) == before
    forced = _post(guarded, "drives.csv", payload, allow_implausible="true")
    assert forced.status_code == 201, forced.text
    warnings = forced.json()["report"]["plausibility_warnings"]
    assert warnings and any(words[0] in w for w in warnings)


def test_plausibility_ranges_by_hand() -> None:
    ok = pd.DataFrame({"v_ego": [25.0, 30.0, 35.0], "gap": [10.0, 30.0, 50.0],
                       "lane_width": [3.5, 3.5, 3.75], "p_t": [2.0, 3.0, 4.0]})
    assert implausible(ok) == []
    kmh = ok.assign(v_ego=ok["v_ego"] * 3.6)  # median 108 "m/s"
    assert [m.split(" = ")[0] for m in implausible(kmh)] == ["median ego speed v_ego"]
    one_odd = ok.assign(gap=[10.0, 30.0, 90_000.0])  # a median is not moved by one event
    assert implausible(one_odd) == []
