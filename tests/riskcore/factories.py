"""Data factories for riskcore tests: surfaces, tracks and scenarios built in code."""

from __future__ import annotations

import numpy as np

from riskcore import ConcreteScenario, InputSurfaces, Track

V0 = [0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0]


def paper_like_surfaces(turn_base: float = 0.02, turn_slope: float = 0.2,
                        turn_bias: float = 0.0) -> InputSurfaces:
    """The qualitative shape of the paper's Fig. 2 text, explicit (not the packaged file).

    mean = 0.9 x0 (+ turn_bias for the turn rate, to break the left/right symmetry);
    accel std = (0.3 + 0.3 |a0|) · 30 / (v0 + 15);
    turn std = (turn_base + turn_slope |ω0|) · 30 / (v0 + 15).
    """
    a0 = [float(x) for x in np.arange(-6.0, 4.5, 1.0)]
    w0 = [round(float(x), 2) for x in np.arange(-0.5, 0.501, 0.05)]

    def grid(x0: list[float], base: float, slope: float, bias: float) -> dict[str, object]:
        return {"v0": V0, "x0": x0,
                "mean": [[0.9 * x + bias for x in x0] for _ in V0],
                "std": [[(base + slope * abs(x)) * 30.0 / (v + 15.0) for x in x0] for v in V0]}

    return InputSurfaces.from_dict({
        "format": "scengen.input-surfaces/1", "interim": True, "source": "tests",
        "accel": grid(a0, 0.3, 0.3, 0.0), "turn": grid(w0, turn_base, turn_slope, turn_bias)})


def straight_track(track_id: str, t: np.ndarray, x0: float, y0: float, v: float,
                   length: float = 4.5, width: float = 1.8) -> Track:
    """Constant velocity along +x."""
    return Track(track_id, length, width, x=x0 + v * t, y=np.full(t.shape, y0),
                 psi=np.zeros(t.shape), v=np.full(t.shape, v))


def two_vehicle_scenario(t: np.ndarray, ego: Track, obj: Track) -> ConcreteScenario:
    return ConcreteScenario(t=t, ego=ego, objects=(obj,))
