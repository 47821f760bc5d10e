"""The ego-centric format: round trips, validation errors, scenario conversion, extraction."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from datasets.cutin_model import (
    CutInParams,
    crossing_time,
    lateral_displacement,
    motion,
    speed,
)
from datasets.egocentric import (
    EGO_COLUMNS,
    egocentric_to_scenarios,
    event_to_scenario,
    read_egocentric,
    scenario_to_egocentric,
    validate_egocentric,
    write_egocentric,
)
from datasets.errors import FormatError
from datasets.extract import extract_egocentric, extract_egocentric_report
from riskcore.scenario import ConcreteScenario, Track

LANE = 3.6
L_EGO, L_CUT = 4.5, 4.8


def _scenario(p: CutInParams, v_ego: float, x_cut0: float, lead_in: float = 2.5
              ) -> ConcreteScenario:
    """Ego at y = 0 with constant speed; cutter from the neighbouring lane by cutin_model."""
    t = np.round(np.arange(0.0, 12.0 + 1e-9, 0.1), 10)
    m = motion(p, t - lead_in)
    y0 = -LANE if p.p_y1 > 0 else LANE
    ego = Track("ego", L_EGO, 1.8, x=v_ego * t, y=np.zeros_like(t), psi=np.zeros_like(t),
                v=np.full_like(t, v_ego))
    cut = Track("cutter", L_CUT, 1.9, x=x_cut0 + m.x, y=y0 + m.y, psi=m.psi, v=m.v)
    return ConcreteScenario(t=t, ego=ego, objects=(cut,), params=p.as_dict(),
                            provenance={"lane_width": LANE})


def _truth(p: CutInParams, v_ego: float, x_cut0: float, lead_in: float = 2.5
           ) -> tuple[float, float]:
    tau_c = crossing_time(p, LANE / 2)
    x_c = x_cut0 + float(motion(p, [tau_c]).x[0])
    x_e = v_ego * (lead_in + tau_c)
    return v_ego - float(speed(p, tau_c)), x_c - x_e - 0.5 * (L_EGO + L_CUT)


P_LEFT = CutInParams(p_y1=0.06, p_t=2.0, p_a1=-0.8, p_a2=0.5, p_a3=1.5, p_v0=24.0,
                     dv=0.0, gap=0.0)


def test_scenario_to_egocentric_by_hand() -> None:
    sc = _scenario(P_LEFT, 27.0, 110.0)
    ev = scenario_to_egocentric(sc, "e1")
    assert list(ev.columns) == list(EGO_COLUMNS)
    assert len(ev) == len(sc.t)
    assert ev["target_dy"].iloc[0] == pytest.approx(-LANE)
    # cutter at x = 110 m at tau = 0, 2.5 s earlier at 24 m/s: 110 - 60 = 50 m
    assert ev["target_dx"].iloc[0] == pytest.approx(50.0)
    assert (ev["lane_width"] == LANE).all()
    assert (ev["ego_y"] == 0.0).all()
    assert (ev["event_id"] == "e1").all()


def test_scenario_round_trip_recovers_parameters() -> None:
    """Built scenario -> ego-centric -> extraction gives the vector back."""
    rows = []
    cases = [(P_LEFT, 27.0, 110.0),
             (CutInParams(p_y1=-0.025, p_t=2.6, p_a1=0.6, p_a2=-0.5, p_a3=2.0, p_v0=30.0,
                          dv=0.0, gap=0.0), 28.0, 100.0)]
    for k, (p, v_ego, x0) in enumerate(cases):
        rows.append(scenario_to_egocentric(_scenario(p, v_ego, x0), f"e{k}"))
    table = extract_egocentric(pd.concat(rows), source="built")
    assert len(table) == 2
    for k, (p, v_ego, x0) in enumerate(cases):
        row = table.iloc[k]
        dv, gap = _truth(p, v_ego, x0)
        assert row["event_id"] == f"e{k}"
        assert row["p_t"] == pytest.approx(p.p_t, rel=0.02)
        assert row["p_y1"] == pytest.approx(p.p_y1, rel=0.03)
        assert row["p_v0"] == pytest.approx(p.p_v0, abs=0.05)
        assert row["p_a1"] == pytest.approx(p.p_a1, abs=0.05)
        assert row["p_a2"] == pytest.approx(p.p_a2, abs=0.1)
        assert row["p_a3"] == pytest.approx(p.p_a3, abs=0.1)
        assert row["dv"] == pytest.approx(dv, abs=0.05)
        assert row["gap"] == pytest.approx(gap, abs=0.1)
        assert row["side"] == ("right" if p.p_y1 > 0 else "left")
        assert row["lane_width"] == LANE
        assert row["t_start"] == pytest.approx(2.5, abs=0.05)
        assert row["v_ego"] == pytest.approx(v_ego)
        assert row["thw"] == pytest.approx(gap / v_ego, abs=0.01)


def test_extraction_skips_cut_out_with_reason() -> None:
    sc = _scenario(P_LEFT, 27.0, 110.0)
    ev = scenario_to_egocentric(sc, "out")
    # mirror the lateral motion about the start lane: from -3.6 m out to -7.2 m
    ev["target_dy"] = -2.0 * LANE - ev["target_dy"]
    res = extract_egocentric_report(ev)
    assert len(res.table) == 0
    assert res.skipped and res.skipped[0][0] == "out"


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz", ".parquet"])
def test_write_read_round_trip_is_exact(tmp_path: Path, suffix: str) -> None:
    ev = pd.concat([scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a"),
                    scenario_to_egocentric(_scenario(P_LEFT, 25.0, 100.0), "b")])
    path = write_egocentric(ev, tmp_path / f"ev{suffix}")
    back = read_egocentric(path)
    pd.testing.assert_frame_equal(back, validate_egocentric(ev), check_exact=True)


def test_missing_column_is_named(tmp_path: Path) -> None:
    ev = scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a").drop(columns="target_v")
    path = tmp_path / "bad.csv"
    ev.to_csv(path, index=False)
    with pytest.raises(FormatError, match=r"bad.csv: missing column\(s\) target_v"):
        read_egocentric(path)


def test_unparsable_value_names_column_and_row(tmp_path: Path) -> None:
    ev = scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a")
    ev["ego_v"] = ev["ego_v"].astype(object)
    ev.loc[7, "ego_v"] = "fast"
    path = tmp_path / "bad.csv"
    ev.to_csv(path, index=False)
    with pytest.raises(FormatError, match=r"bad.csv: column 'ego_v', row 7: value 'fast'"):
        read_egocentric(path)


def test_other_validation_errors() -> None:
    ev = scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a")
    bad = ev.copy()
    bad.loc[3, "target_v"] = -1.0
    with pytest.raises(FormatError, match=r"column 'target_v', row 3: speed -1.0 < 0"):
        validate_egocentric(bad)
    bad = ev.copy()
    bad.loc[4, "t"] = bad.loc[3, "t"]
    with pytest.raises(FormatError, match="time repeats within event 'a'"):
        validate_egocentric(bad)
    bad = ev.copy()
    bad.loc[2, "ego_length"] = 0.0
    with pytest.raises(FormatError, match="ego_length"):
        validate_egocentric(bad)
    with pytest.raises(FormatError, match="unknown file type"):
        write_egocentric(ev, "/tmp/x.txt")
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_egocentric("/nonexistent/ev.csv")


def test_optional_columns_may_be_absent() -> None:
    ev = scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a")
    out = validate_egocentric(ev.drop(columns=["ego_y", "lane_width"]))
    assert out["ego_y"].isna().all() and out["lane_width"].isna().all()
    # without the lane width the crossing is the midpoint of the fitted displacement
    table = extract_egocentric(out)
    assert len(table) == 1
    # (the cutter's own lateral displacement, here 3.52 m, not the builder's 3.6 m lane)
    assert table["lane_width"].iloc[0] == pytest.approx(lateral_displacement(P_LEFT), abs=0.02)


def test_event_to_scenario_by_hand() -> None:
    """Three rows, 0.5 s apart: ego at 20 then 22 then 24 m/s (trapezoid: x = 0, 10.5,
    22 m); target 30 m ahead and 3.5 m left, moving 1 m right per step."""
    ev = pd.DataFrame({
        "event_id": ["a"] * 3, "t": [10.0, 10.5, 11.0], "ego_v": [20.0, 22.0, 24.0],
        "target_dx": [30.0, 30.0, 30.0], "target_dy": [3.5, 2.5, 1.5],
        "target_v": [20.0, 22.0, 24.0], "ego_length": [4.5] * 3, "ego_width": [1.8] * 3,
        "target_length": [4.0] * 3, "target_width": [1.7] * 3,
        "ego_y": [0.0] * 3, "lane_width": [3.5] * 3})
    sc = egocentric_to_scenarios(ev)["a"]
    np.testing.assert_allclose(sc.t, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(sc.ego.x, [0.0, 10.5, 22.0])
    np.testing.assert_allclose(sc.objects[0].x, [30.0, 40.5, 52.0])
    np.testing.assert_allclose(sc.objects[0].y, [3.5, 2.5, 1.5])
    # heading from the velocity by central differences: middle step dx/dt = 22, dy/dt = -2
    assert sc.objects[0].psi[1] == pytest.approx(np.arctan2(-2.0, 22.0))
    np.testing.assert_allclose(sc.ego.psi, 0.0)
    assert (sc.ego.length, sc.objects[0].width) == (4.5, 1.7)
    assert sc.objects[0].id == "cutter"
    assert sc.provenance == {"source": "egocentric", "event_id": "a", "lane_width": 3.5}


def test_scenario_egocentric_scenario_round_trip() -> None:
    """scenario -> ego-centric -> scenario keeps the relative motion and the speeds."""
    sc = _scenario(P_LEFT, 27.0, 110.0)
    back = event_to_scenario(validate_egocentric(scenario_to_egocentric(sc, "e")))
    np.testing.assert_allclose(back.t, sc.t - sc.t[0])
    np.testing.assert_allclose(back.objects[0].x - back.ego.x,
                               sc.objects[0].x - sc.ego.x, atol=1e-9)
    np.testing.assert_allclose(back.objects[0].y - back.ego.y,
                               sc.objects[0].y - sc.ego.y, atol=1e-12)
    np.testing.assert_allclose(back.ego.x, sc.ego.x - sc.ego.x[0], atol=1e-9)
    np.testing.assert_allclose(back.objects[0].v, sc.objects[0].v)
    assert back.provenance["lane_width"] == pytest.approx(LANE)


def test_event_to_scenario_refuses_two_events() -> None:
    ev = validate_egocentric(pd.concat([
        scenario_to_egocentric(_scenario(P_LEFT, 27.0, 110.0), "a"),
        scenario_to_egocentric(_scenario(P_LEFT, 25.0, 100.0), "b")]))
    with pytest.raises(FormatError, match="one event"):
        event_to_scenario(ev)
