"""Input surfaces (eq. 2): file format, bilinear interpolation, clamping, mirroring."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riskcore import InputSurfaces, Surface, SurfaceError
from riskcore.surfaces import FORMAT


def _doc() -> dict[str, object]:
    surf = {"v0": [0.0, 10.0], "x0": [-1.0, 1.0], "mean": [[0.0, 2.0], [4.0, 6.0]],
            "std": [[1.0, 1.0], [0.5, 0.5]], "count": [[3, 4], [5, 6]]}
    return {"format": FORMAT, "interim": False, "source": "hand", "notes": "",
            "accel": surf, "turn": json.loads(json.dumps(surf))}


def test_packaged_default_loads_and_says_what_it_is() -> None:
    s = InputSurfaces.load(None)
    assert s.accel.mean.shape == (s.accel.v0.size, s.accel.x0.size)
    assert s.turn.std.min() > 0
    if s.interim:  # the interim file must say it is hand-made
        assert "INTERIM" in s.notes and "hand-made" in s.notes


def test_bilinear_interpolation_by_hand() -> None:
    s = InputSurfaces.from_dict(_doc())
    mean, std = s.accel(5.0, 0.0)
    assert float(mean) == 3.0 and float(std) == 0.75
    mean, _ = s.accel(2.5, 0.5)  # rows 1.5 and 5.5, a quarter of the way: 2.5
    assert math.isclose(float(mean), 2.5, rel_tol=1e-15)
    # clamped at the edges
    assert float(s.accel(-5.0, -3.0)[0]) == 0.0
    assert float(s.accel(100.0, 100.0)[0]) == 6.0
    assert float(s.turn(100.0, 0.0)[0]) == 5.0
    # arrays broadcast
    mean, std = s.accel(np.array([[0.0], [10.0]]), np.array([-1.0, 1.0]))
    np.testing.assert_array_equal(mean, [[0.0, 2.0], [4.0, 6.0]])
    assert std.shape == (2, 2)


def test_a_single_cell_is_a_constant() -> None:
    doc = _doc()
    doc["turn"] = {"v0": [0.0], "x0": [0.0], "mean": [[0.1]], "std": [[0.02]]}
    s = InputSurfaces.from_dict(doc)
    assert tuple(float(q) for q in s.turn(33.0, -0.4)) == (0.1, 0.02)


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    s = InputSurfaces.from_dict(_doc())
    path = tmp_path / "s.json"
    s.save(path)
    back = InputSurfaces.load(path)
    assert back.to_dict() == s.to_dict()
    assert back.to_dict()["accel"]["count"] == [[3.0, 4.0], [5.0, 6.0]]


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda d: d.update(extra=1), "unknown field"),
    (lambda d: d.update(format="x"), "format"),
    (lambda d: d.pop("turn"), "turn: missing"),
    (lambda d: d["accel"].update(v0=[10.0, 0.0]), r"accel.v0\[1\]"),
    (lambda d: d["accel"].update(std=[[1.0, 0.0], [1.0, 1.0]]), r"accel.std\[0\]\[1\]"),
    (lambda d: d["turn"].update(mean=[[0.0, 1.0]]), "turn.mean: shape"),
    (lambda d: d["turn"].update(mean=[[0.0, math.nan], [0.0, 0.0]]), r"turn.mean\[0\]\[1\]"),
    (lambda d: d["turn"].update(count=[[1, -1], [0, 0]]), "turn.count"),
    (lambda d: d["turn"].update(sigma=[[1]]), "turn: unknown field"),
    (lambda d: d.update(interim="yes"), "interim"),
])
def test_bad_surfaces_name_the_field(mutate, message: str) -> None:  # type: ignore[no-untyped-def]
    doc = json.loads(json.dumps(_doc()))
    mutate(doc)
    with pytest.raises(SurfaceError, match=message):
        InputSurfaces.from_dict(doc)


def test_bad_files(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    path.write_text(json.dumps(_doc()).replace("6.0", "NaN"))
    with pytest.raises(SurfaceError, match="NaN"):
        InputSurfaces.load(path)
    path.write_text("{")
    with pytest.raises(SurfaceError, match="not valid JSON"):
        InputSurfaces.load(path)
    with pytest.raises(OSError):
        InputSurfaces.load(tmp_path / "missing.json")


finite = {"allow_nan": False, "allow_infinity": False}


@settings(max_examples=50, deadline=None)
@given(st.data())
def test_mirrored_turn_surface(data: st.DataObject) -> None:
    nv, nx = data.draw(st.integers(1, 4)), data.draw(st.integers(1, 5))
    x0 = np.cumsum(data.draw(st.lists(st.floats(0.01, 0.2), min_size=nx, max_size=nx))) - 0.3
    surf = Surface(v0=np.arange(nv) * 10.0, x0=x0,
                   mean=np.array(data.draw(st.lists(st.floats(-1, 1, **finite),
                                                    min_size=nv * nx, max_size=nv * nx))
                                 ).reshape(nv, nx),
                   std=np.array(data.draw(st.lists(st.floats(0.01, 1, **finite),
                                                   min_size=nv * nx, max_size=nv * nx))
                                ).reshape(nv, nx))
    s = InputSurfaces(accel=surf, turn=surf)
    m = s.mirrored()
    v = data.draw(st.floats(-5, 40, **finite))
    w = data.draw(st.floats(-0.6, 0.6, **finite))
    mean, std = s.turn(v, w)
    mean_m, std_m = m.turn(v, -w)
    assert math.isclose(float(mean_m), -float(mean), rel_tol=1e-12, abs_tol=1e-14)
    assert math.isclose(float(std_m), float(std), rel_tol=1e-12)
    assert m.accel is s.accel
    assert m.mirrored().turn.to_dict() == s.turn.to_dict()
