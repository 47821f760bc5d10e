"""highD: hand-written files, road-frame conversion, cut-in cases, errors, round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datasets.cutin_model import crossing_time, motion, speed
from datasets.errors import FormatError
from datasets.extract import extract_cutins, extract_highd, extract_highd_report
from datasets.highd import find_recordings, read_highd, road_frame, write_highd
from datasets.highd_extract import find_cutins
from tests.datasets.highd_factory import (
    CENTRE,
    FPS,
    WIDTH,
    chain,
    changing,
    make_recording,
    p_for_lane_change,
    straight,
)

TRACKS = """\
frame,id,x,y,width,height,xVelocity,yVelocity,xAcceleration,yAcceleration,\
frontSightDistance,backSightDistance,dhw,thw,ttc,precedingXVelocity,precedingId,followingId,\
leftPrecedingId,leftAlongsideId,leftFollowingId,rightPrecedingId,rightAlongsideId,\
rightFollowingId,laneId
1,1,300.00,6.70,4.00,1.80,-30.00,0.50,-0.20,0.10,0,0,0,0,0,0,0,0,0,0,0,0,0,0,3
2,1,298.80,6.72,4.00,1.80,-30.00,0.50,-0.20,0.10,0,0,0,0,0,0,0,0,0,0,0,0,0,0,3
1,2,50.00,17.00,5.00,2.00,25.00,-0.40,0.30,-0.05,0,0,0,0,0,0,0,0,0,0,0,0,0,0,6
2,2,51.00,16.98,5.00,2.00,25.00,-0.40,0.30,-0.05,0,0,0,0,0,0,0,0,0,0,0,0,0,0,6
"""
TRACKS_META = """\
id,width,height,initialFrame,finalFrame,numFrames,class,drivingDirection,traveledDistance,\
minXVelocity,maxXVelocity,meanXVelocity,minDHW,minTHW,minTTC,numLaneChanges
1,4.00,1.80,1,2,2,Car,1,1.2,30,30,30,-1,-1,-1,0
2,5.00,2.00,1,2,2,Car,2,1.0,25,25,25,-1,-1,-1,0
"""
RECORDING_META = """\
id,frameRate,locationId,speedLimit,month,weekDay,startTime,duration,totalDrivenDistance,\
totalDrivenTime,numVehicles,numCars,numTrucks,upperLaneMarkings,lowerLaneMarkings
3,25,2,-1.00,09.2017,Tue,08:38,0.08,2.2,0.16,2,2,0,2.00;5.75;9.50,13.00;16.75;20.50
"""


def _write_hand_files(d: Path, tracks: str = TRACKS, meta: str = TRACKS_META,
                      rec: str = RECORDING_META) -> Path:
    (d / "03_tracks.csv").write_text(tracks)
    (d / "03_tracksMeta.csv").write_text(meta)
    (d / "03_recordingMeta.csv").write_text(rec)
    return d / "03"


def test_road_frame_by_hand(tmp_path: Path) -> None:
    road = road_frame(read_highd(_write_hand_files(tmp_path)))
    one = road[road["id"] == 1].reset_index(drop=True)
    two = road[road["id"] == 2].reset_index(drop=True)
    # direction 1 (upper lanes, driving to -x in the image): rotated by 180 degrees
    # centre = corner + half size: x 300 + 2 = 302 -> road x = -302; y 6.7 + 0.9 = 7.6
    assert one["x"].tolist() == pytest.approx([-302.0, -300.8])
    assert one["y"].tolist() == pytest.approx([7.6, 7.62])
    assert one["vx"].tolist() == pytest.approx([30.0, 30.0])  # forward along the road
    assert one["vy"].tolist() == pytest.approx([0.5, 0.5])  # image +y = towards the median = left
    assert one["ax"][0] == pytest.approx(0.2) and one["ay"][0] == pytest.approx(0.1)
    assert one["length"][0] == 4.0 and one["width"][0] == 1.8
    # direction 2 (lower lanes, driving to +x): y flipped (image y points down)
    assert two["x"].tolist() == pytest.approx([52.5, 53.5])
    assert two["y"].tolist() == pytest.approx([-18.0, -17.98])
    assert two["vx"][0] == 25.0 and two["vy"][0] == pytest.approx(0.4)  # up in the image = left
    assert two["t"].tolist() == pytest.approx([1 / 25, 2 / 25])
    # x grows along the driving direction in both directions
    assert (np.diff(one["x"]) > 0).all() and (np.diff(two["x"]) > 0).all()


def test_marking_and_lane_geometry(tmp_path: Path) -> None:
    rec = read_highd(_write_hand_files(tmp_path))
    assert rec.lane_width(2) == pytest.approx(3.75)
    assert rec.marking_road(2, 3) == pytest.approx(5.75)  # direction 1 keeps image y
    assert rec.marking_road(5, 6) == pytest.approx(-16.75)  # direction 2 flips it
    assert rec.lane_direction(3) == 1 and rec.lane_direction(5) == 2
    with pytest.raises(FormatError, match="not adjacent"):
        rec.marking_road(2, 5)
    assert not rec.is_synthetic


@pytest.mark.parametrize(("which", "text", "pattern"), [
    ("tracks", TRACKS.replace("-30.00,0.50,-0.20", "-30.00,abc,-0.20", 1),
     r"03_tracks.csv: column 'yVelocity', row 0 \(line 2\): value 'abc'"),
    ("tracks", TRACKS.replace(",laneId", ",lane").replace(",3\n", ",3\n"),
     r"03_tracks.csv: missing column\(s\) laneId"),
    ("tracks", TRACKS.replace("2,2,51.00", "2,2.5,51.00"),
     r"03_tracks.csv: column 'id', row 3 \(line 5\): value 2.5 is not an integer"),
    ("meta", TRACKS_META.replace("Car,2,", "Car,7,"),
     r"03_tracksMeta.csv: column 'drivingDirection', row 1: expected 1 or 2"),
    ("meta", TRACKS_META.replace("2,5.00,2.00", "9,5.00,2.00"),
     r"03_tracks.csv: column 'id', row 2: track id 2 has no row in 03_tracksMeta.csv"),
    ("rec", RECORDING_META.replace("2.00;5.75;9.50", "2.00;x;9.50"),
     r"upperLaneMarkings: expected numbers separated by ';'"),
])
def test_errors_name_file_column_row(tmp_path: Path, which: str, text: str,
                                     pattern: str) -> None:
    kw = {"tracks": TRACKS, "meta": TRACKS_META, "rec": RECORDING_META}
    kw[which] = text
    prefix = _write_hand_files(tmp_path, kw["tracks"], kw["meta"], kw["rec"])
    with pytest.raises(FormatError, match=pattern):
        read_highd(prefix)


def test_missing_file_is_named(tmp_path: Path) -> None:
    prefix = _write_hand_files(tmp_path)
    (tmp_path / "03_tracksMeta.csv").unlink()
    with pytest.raises(FileNotFoundError, match=r"03_tracksMeta\.csv: missing highD file"):
        read_highd(prefix)
    with pytest.raises(FileNotFoundError, match="not a highD folder"):
        find_recordings(tmp_path / "nothing_here")


def _truth(p, t0, s_cut_t0, ego, width=WIDTH):  # type: ignore[no-untyped-def]
    """(dv, gap) of a cut-in by the model: crossing when |y - y_start| = width / 2."""
    tau_c = crossing_time(p, width / 2)
    t_c = t0 + tau_c
    x_c = s_cut_t0 + float(motion(p, [tau_c]).x[0])
    x_e = float(np.interp(t_c, ego.frames / FPS, ego.s))
    v_e = float(np.interp(t_c, ego.frames / FPS, ego.v))
    return v_e - float(speed(p, tau_c)), x_c - x_e - 4.5, t_c


def test_direction_2_cut_in_from_the_right(tmp_path: Path) -> None:
    # lower lanes: the cutter leaves lane 6 (right) for lane 5 (left) in front of the ego
    p = p_for_lane_change(left=True, p_t=2.0, v=26.0, p_a1=-0.5, p_a2=0.5, p_a3=1.5)
    cutter = changing(1, 2, 6, s_at_t0=150.0, t0=3.0, p=p)
    ego = straight(2, 2, 5, s0=20.0, v=30.0)
    rec = make_recording([cutter, ego])
    write_highd(rec, tmp_path)
    res = extract_cutins(tmp_path, "highd")
    assert res.skipped == []
    assert len(res.table) == 1
    row = res.table.iloc[0]
    dv, gap, t_c = _truth(p, 3.0, 150.0, ego)
    assert (row["cutter_id"], row["ego_id"], row["side"]) == ("1", "2", "right")
    assert row["p_y1"] > 0
    assert row["p_t"] == pytest.approx(2.0, rel=0.02)
    assert row["dv"] == pytest.approx(dv, abs=0.05)
    assert row["gap"] == pytest.approx(gap, abs=0.05)
    assert row["t_cross"] == pytest.approx(t_c, abs=0.01)
    assert row["t_start"] == pytest.approx(3.0, abs=0.05)
    assert row["lane_width"] == pytest.approx(3.75)
    assert row["p_a1"] == pytest.approx(-0.5, abs=0.05)
    assert row["source"] == "07"


def test_direction_1_cut_in_from_the_left(tmp_path: Path) -> None:
    # upper lanes: the cutter leaves lane 3 (left, next to the median) for lane 2 (right)
    p = p_for_lane_change(left=False, p_t=2.5, v=32.0)
    cutter = changing(1, 1, 3, s_at_t0=140.0, t0=3.5, p=p)
    ego = straight(2, 1, 2, s0=20.0, v=28.0)
    table = extract_highd(make_recording([cutter, ego]))
    assert len(table) == 1
    row = table.iloc[0]
    dv, gap, _ = _truth(p, 3.5, 140.0, ego)
    assert (row["side"], row["cutter_id"], row["ego_id"]) == ("left", "1", "2")
    assert row["p_y1"] < 0
    assert row["p_y1"] == pytest.approx(p.p_y1, rel=0.03)
    assert row["dv"] == pytest.approx(dv, abs=0.05)
    assert row["gap"] == pytest.approx(gap, abs=0.05)


def test_lane_change_with_no_vehicle_behind_is_not_a_cut_in() -> None:
    p = p_for_lane_change(left=True, p_t=2.0, v=26.0)
    cutter = changing(1, 2, 6, s_at_t0=150.0, t0=3.0, p=p)
    ahead = straight(2, 2, 5, s0=250.0, v=30.0)  # in the target lane, but in front
    rec = make_recording([cutter, ahead])
    changes = find_cutins(road_frame(rec))
    assert len(changes) == 1 and not changes["is_cutin"].iloc[0]
    res = extract_highd_report(rec)
    assert len(res.table) == 0 and res.skipped == []


def test_vehicle_changing_lane_twice(tmp_path: Path) -> None:
    # 6 -> 5 starting at 1 s, back 5 -> 6 starting at 7 s; a follower in each target lane
    p1 = p_for_lane_change(left=True, p_t=1.5, v=28.0)
    p2 = p_for_lane_change(left=False, p_t=1.6, v=28.0)
    cutter = chain(changing(1, 2, 6, s_at_t0=120.0, t0=1.0, p=p1), p2, 7.0)
    ego_a = straight(2, 2, 5, s0=60.0, v=29.0)
    ego_b = straight(3, 2, 6, s0=30.0, v=30.0)
    rec = make_recording([cutter, ego_a, ego_b])
    assert int(rec.tracks_meta.loc[0, "numLaneChanges"]) == 2
    table = extract_highd(rec).sort_values("t_start").reset_index(drop=True)
    assert table["ego_id"].tolist() == ["2", "3"]
    assert table["side"].tolist() == ["right", "left"]
    assert table["p_t"].tolist() == pytest.approx([1.5, 1.6], rel=0.03)
    assert table["t_start"].tolist() == pytest.approx([1.0, 7.0], abs=0.05)
    assert table["event_id"].is_unique


def test_write_read_round_trip(tmp_path: Path) -> None:
    p = p_for_lane_change(left=True, p_t=2.0, v=26.0)
    rec = make_recording([changing(1, 2, 6, 150.0, 3.0, p), straight(2, 2, 5, 70.0, 30.0),
                          straight(3, 1, 2, 10.0, 25.0)])
    paths = write_highd(rec, tmp_path)
    back = read_highd(tmp_path / "07")
    for name in ("tracks", "tracks_meta", "recording_meta"):
        ours = getattr(rec, name)
        theirs = getattr(back, name)
        assert list(theirs.columns) == list(ours.columns)
        for col in ours.columns:
            np.testing.assert_array_equal(theirs[col].to_numpy(), ours[col].to_numpy())
    # and writing again gives the same bytes
    again = write_highd(back, tmp_path / "again")
    for a, b in zip(paths, again, strict=True):
        assert a.read_bytes() == b.read_bytes()
    pd.testing.assert_frame_equal(road_frame(back), road_frame(rec), check_exact=True)
    assert CENTRE[5] == -14.875  # the factory's lane centres match the markings


@settings(max_examples=20, deadline=None)
@given(direction=st.sampled_from([1, 2]), lane_left=st.booleans(),
       s0=st.floats(0.0, 300.0), v=st.floats(5.0, 45.0), length=st.floats(3.0, 18.0))
def test_road_frame_property_recovers_the_road_state(
    direction: int, lane_left: bool, s0: float, v: float, length: float
) -> None:
    """Road state -> image (the factory's plain code) -> road_frame gives it back; x grows
    along the driving direction whatever the direction."""
    lane = {(1, False): 2, (1, True): 3, (2, False): 6, (2, True): 5}[(direction, lane_left)]
    veh = straight(1, direction, lane, s0=s0, v=v, n=5, length=length)
    road = road_frame(make_recording([veh]))
    assert road["y"].to_numpy() == pytest.approx(np.full(5, CENTRE[lane]))
    assert road["vx"].to_numpy() == pytest.approx(np.full(5, v))
    assert np.diff(road["x"].to_numpy()) == pytest.approx(np.full(4, v / FPS))
    assert (road["length"] == length).all()
    # a vehicle in the left lane of its direction is at larger road y
    assert (CENTRE[3] > CENTRE[2]) and (CENTRE[5] > CENTRE[6])
