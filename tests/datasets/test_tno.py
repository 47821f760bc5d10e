"""TNO converter: a hand-made JSON with known values, implausible events, the real file."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from datasets.egocentric import read_egocentric
from datasets.embedded import DEFAULT_EVENTS_PATH
from datasets.errors import FormatError
from datasets.tno import EGO_SIZE, TARGET_SIZE, convert_tno

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "tno-cutin" / "cut-in.json"
KNOTS = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]


def _const(c: float) -> dict[str, Any]:
    return {"knots": KNOTS, "coefficients": [c] * 4, "degree": 3}


def _linear(a: float, b: float) -> dict[str, Any]:
    # a cubic Bezier with equally spaced control points is the straight line a -> b
    return {"knots": KNOTS, "coefficients": list(np.linspace(a, b, 4)), "degree": 3}


def _tno(v_target: float = 25.0, dy: tuple[float, float] = (-3.5, 0.0),
         t_lc: tuple[float, float] = (12.0, 16.0)) -> dict[str, Any]:
    times = {"1": 0.0, "2": 30.0, "3": t_lc[0], "4": t_lc[1]}
    event = {k: {"conditions": {"time": v}} for k, v in times.items()}
    lon = {"id": "a1", "name": "cruising target", "start": {"uid": 1}, "end": {"uid": 2},
           "category": {"uid": 100},
           "parameters": {"knots": [KNOTS, KNOTS],
                          "coefficients": [[v_target] * 4, [20.0] * 4], "degree": [3, 3]}}
    lat = {"id": "a2", "name": "left lane change", "start": {"uid": 3}, "end": {"uid": 4},
           "category": {"uid": 101}, "parameters": _linear(*dy)}
    spd = {"id": "a3", "name": "cruising ego", "start": {"uid": 1}, "end": {"uid": 2},
           "category": {"uid": 102}, "parameters": _const(27.0)}
    return {
        "activity": {"a1": lon, "a2": lat, "a3": spd},
        "activity_category": {"100": {"state": {"name": "LON_TARGET"}},
                              "101": {"state": {"name": "LAT_TARGET"}},
                              "102": {"state": {"name": "SPEED"}}},
        "event": event,
        "scenario": {"s1": {"actors": [{"name": "ego vehicle", "uid": 9},
                                       {"name": "target vehicle", "uid": 8}],
                            "acts": [{"actor": 8, "activity": "a1"},
                                     {"actor": 8, "activity": "a2"},
                                     {"actor": 9, "activity": "a3"}]}},
    }


def test_hand_made_scenario_values(tmp_path: Path) -> None:
    path = tmp_path / "cut-in.json"
    path.write_text(json.dumps(_tno()))
    conv = convert_tno(path, rate=10.0, pre=3.0, post=3.0)
    assert conv.rejected == [] and conv.n_scenarios == 1
    f = conv.frame
    assert f["event_id"].unique().tolist() == ["tno-001"]
    # 9 s to 19 s at 10 Hz
    assert f["t"].iloc[0] == pytest.approx(9.0) and f["t"].iloc[-1] == pytest.approx(19.0)
    assert len(f) == 101
    mid = f.loc[np.isclose(f["t"], 14.0)].iloc[0]
    assert mid["target_dy"] == pytest.approx(-1.75)  # halfway along the straight line
    assert f["target_dy"].iloc[0] == pytest.approx(-3.5)  # held before the lane change
    assert f["target_dy"].iloc[-1] == pytest.approx(0.0, abs=1e-12)  # held after it
    # dx read as bumper-to-bumper: centre distance = 20 + (4.6 + 4.6) / 2
    assert f["target_dx"].to_numpy() == pytest.approx(20.0 + 0.5 * (EGO_SIZE[0] + TARGET_SIZE[0]))
    assert f["target_v"].to_numpy() == pytest.approx(25.0)
    assert f["ego_v"].to_numpy() == pytest.approx(27.0)
    assert (f["lane_width"] == 3.5).all() and f["ego_y"].isna().all()


@pytest.mark.parametrize(("kw", "reason"), [
    ({"v_target": 0.5}, "target speed near 0"),
    ({"t_lc": (12.0, 12.6)}, "lane change shorter than 1 s"),
    ({"dy": (-3.5, -3.2)}, "lateral displacement 0.30 m below 1 m"),
    ({"dy": (-3.5, -2.0)}, "never crosses the lane marking"),
    ({"dy": (-1.0, 3.0)}, "does not move towards the ego"),
    ({"dy": (-25.0, 0.0), "t_lc": (12.0, 16.0)}, "lateral speed"),
])
def test_implausible_events_are_left_out_with_reasons(tmp_path: Path, kw: dict[str, Any],
                                                      reason: str) -> None:
    path = tmp_path / "cut-in.json"
    path.write_text(json.dumps(_tno(**kw)))
    with pytest.raises(FormatError, match="no plausible cut-in events"):
        convert_tno(path)
    data = _tno(**kw)
    good = _tno()
    # the good scenario with its own activity ids b1..b3
    for key in ("a1", "a2", "a3"):
        data["activity"]["b" + key[1]] = good["activity"][key]
    data["event"]["5"] = good["event"]["3"]
    data["event"]["6"] = good["event"]["4"]
    data["activity"]["b2"] = {**good["activity"]["a2"], "start": {"uid": 5}, "end": {"uid": 6}}
    text = json.dumps(good["scenario"]["s1"])
    for key in ("a1", "a2", "a3"):
        text = text.replace(f'"{key}"', f'"b{key[1]}"')
    scen = json.loads(text)
    data["scenario"]["s2"] = scen
    path.write_text(json.dumps(data))
    conv = convert_tno(path)
    assert len(conv.rejected) == 1 and conv.rejected[0][0] == "tno-001"
    assert reason in conv.rejected[0][1]
    assert conv.frame["event_id"].unique().tolist() == ["tno-002"]


def test_bad_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        convert_tno(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(FormatError, match="not readable JSON"):
        convert_tno(bad)
    bad.write_text("{}")
    with pytest.raises(FormatError, match="missing top-level key 'scenario'"):
        convert_tno(bad)


@pytest.mark.skipif(not REAL.is_file(), reason="the shared TNO data is not on this machine")
def test_real_file_matches_the_embedded_data() -> None:
    conv = convert_tno(REAL)
    assert conv.n_scenarios == 297
    kept = conv.frame["event_id"].nunique()
    assert kept + len(conv.rejected) == 297
    reasons = Counter(r.split(" (")[0].split(" below")[0] for _, r in conv.rejected)
    assert reasons["lane change shorter than 1 s"] >= 30  # the README's known outliers
    assert any("target speed near 0" in r for _, r in conv.rejected)
    shipped = read_egocentric(DEFAULT_EVENTS_PATH)
    pd.testing.assert_frame_equal(shipped, conv.frame, check_exact=True)
