"""A whole concrete scenario: one scene per recorded time step, the risk as a time series.

For each time step k of the scenario (time t_k):

- The ego's future is its recorded trajectory on the prediction grid t_k + n·dt,
  n = 0..N, linearly interpolated in x, y, v and the unwrapped heading ψ (so recordings at
  another rate, e.g. 25 Hz, are resampled onto the prediction step). Past the end of the
  recording the ego continues at constant velocity and heading from its last recorded
  state: x = x_end + v_end cos ψ_end (t - t_end), likewise y; ψ and v stay.
- Each object starts from its recorded state at step k (x, y, ψ, v, size). Its current
  inputs are a0 = ``a[k]`` and ω0 = ``yaw_rate[k]`` when the track has them, else finite
  differences of its own recorded v and unwrapped ψ over t (``numpy.gradient``: second-order
  central differences inside, one-sided first-order differences at the two ends).
- The scene is evaluated with :func:`riskcore.scene.evaluate_scene`'s engine.

The scenario risk is the maximum over the steps of the scene risk r_dep (the paper: "the
risk measure for a whole scenario by computing the maximum scene risk").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riskcore.errors import SceneError
from riskcore.evasion import MANOEUVRES, Manoeuvre
from riskcore.scenario import ConcreteScenario, Track
from riskcore.scene import EgoFuture, ObjectState, SceneResult, _Engine, default_surfaces
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces

__all__ = ["RESULT_FORMAT", "ScenarioRisk", "ego_future_at", "evaluate_scenario",
           "object_inputs"]

RESULT_FORMAT = "scengen.scenario-risk/1"

FloatArray = NDArray[np.float64]


def ego_future_at(scenario_t: FloatArray, ego: Track, t_now: float,
                  settings: RiskSettings) -> EgoFuture:
    """The ego's future from ``t_now`` on the prediction grid (see the module docstring).

    Parameters
    ----------
    scenario_t : ndarray of shape (n_t,)
        The scenario's time grid in s.
    ego : Track
        The ego's recorded motion.
    t_now : float
        The scene's time in s.
    settings : RiskSettings

    Returns
    -------
    EgoFuture
        N + 1 points at t_now + n·dt.
    """
    tq = np.asarray(t_now + np.arange(settings.n_steps + 1) * settings.dt, dtype=np.float64)
    psi_u = np.asarray(np.unwrap(ego.psi), dtype=np.float64)
    return _ego_future(scenario_t, ego, tq[None, :], psi_u)[0]


def _ego_future(t: FloatArray, ego: Track, tq: FloatArray,
                psi_u: FloatArray) -> list[EgoFuture]:
    t_end = t[-1]
    after = tq > t_end
    dt_after = np.where(after, tq - t_end, 0.0)
    x_end, y_end, p_end, v_end = ego.x[-1], ego.y[-1], psi_u[-1], ego.v[-1]
    x = np.where(after, x_end + v_end * math.cos(p_end) * dt_after, np.interp(tq, t, ego.x))
    y = np.where(after, y_end + v_end * math.sin(p_end) * dt_after, np.interp(tq, t, ego.y))
    psi = np.where(after, p_end, np.interp(tq, t, psi_u))
    v = np.where(after, v_end, np.interp(tq, t, ego.v))
    return [EgoFuture(x=x[k], y=y[k], psi=psi[k], v=v[k], length=ego.length, width=ego.width)
            for k in range(tq.shape[0])]


def object_inputs(t: FloatArray, track: Track) -> tuple[FloatArray, FloatArray]:
    """Current inputs (a0 in m/s², ω0 in rad/s) of a track at every step.

    ``track.a`` and ``track.yaw_rate`` when given, else ``numpy.gradient`` of v and of the
    unwrapped ψ over ``t``.

    Returns
    -------
    a0, omega0 : ndarray of shape (n_t,)
    """
    a0 = track.a if track.a is not None else np.gradient(track.v, t)
    w0 = track.yaw_rate if track.yaw_rate is not None else np.gradient(np.unwrap(track.psi), t)
    return np.asarray(a0, dtype=np.float64), np.asarray(w0, dtype=np.float64)


def _num(x: float) -> float | None:
    """JSON-safe float: +inf (no collision / not applicable) becomes null."""
    return float(x) if math.isfinite(x) else None


def _nums(arr: Any) -> list[Any]:
    return [_num(float(v)) for v in np.asarray(arr, dtype=np.float64)]


@dataclass(frozen=True, eq=False)
class ScenarioRisk:
    """Risk of a concrete scenario, per time step.

    Attributes
    ----------
    t : ndarray of shape (n_t,)
        The scenario's time steps in s.
    scenes : tuple of SceneResult
        One per time step.
    object_ids : tuple of str
    settings : RiskSettings
    surfaces_source : str
    surfaces_interim : bool
    """

    t: FloatArray
    scenes: tuple[SceneResult, ...]
    object_ids: tuple[str, ...]
    settings: RiskSettings
    surfaces_source: str = ""
    surfaces_interim: bool = False

    # --- series -------------------------------------------------------------------
    def series(self, name: str) -> FloatArray:
        """Per-step series: ``r_dep``, ``r_ind``, ``min_ttr``, ``ttc``, ``wttc``, ``thw``."""
        if name not in ("r_dep", "r_ind", "min_ttr", "ttc", "wttc", "thw"):
            raise KeyError(f"unknown series {name!r}")
        return np.array([float(getattr(s, name)) for s in self.scenes])

    # --- summaries ----------------------------------------------------------------
    @property
    def risk(self) -> float:
        """Scenario risk: the maximum over the steps of r_dep."""
        return float(self.series("r_dep").max())

    @property
    def risk_ind(self) -> float:
        """Maximum over the steps of r_ind."""
        return float(self.series("r_ind").max())

    @property
    def step_of_max_risk(self) -> int:
        """First step index where r_dep reaches its maximum."""
        return int(np.argmax(self.series("r_dep")))

    @property
    def min_ttr(self) -> float:
        return float(self.series("min_ttr").min())

    @property
    def min_ttc(self) -> float:
        return float(self.series("ttc").min())

    @property
    def min_wttc(self) -> float:
        return float(self.series("wttc").min())

    @property
    def min_thw(self) -> float:
        return float(self.series("thw").min())

    @property
    def min_ttr_evasion(self) -> str | None:
        """Evasion label of the smallest TTR over all steps and objects (first step and
        object in order among ties); None when nothing collides."""
        best: tuple[float, str | None] = (math.inf, None)
        for scene in self.scenes:
            for obj in scene.objects:
                if obj.min_ttr < best[0]:
                    best = (obj.min_ttr, obj.min_ttr_evasion)
        return best[1]

    def summary(self) -> dict[str, Any]:
        """Flat JSON-safe dict for tables and exports (+inf as None)."""
        k = self.step_of_max_risk
        return {
            "risk": self.risk, "risk_ind": self.risk_ind, "min_ttr": _num(self.min_ttr),
            "min_ttc": _num(self.min_ttc), "min_wttc": _num(self.min_wttc),
            "min_thw": _num(self.min_thw), "min_ttr_evasion": self.min_ttr_evasion,
            "step_of_max_risk": k, "t_of_max_risk": float(self.t[k]),
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON (no NaN or inf literals): +inf is written as null.

        Layout (``format`` = ``"scengen.scenario-risk/1"``; see docs/riskcore.md)::

            {"format", "settings", "surfaces": {"source", "interim"}, "summary",
             "evasion_bits": {"steer_left": 1, ...},
             "series": {"t", "r_dep", "r_ind", "min_ttr", "ttc", "wttc", "thw"},
             "objects": [{"id", "series": {"risk", "min_ttr", "ttc", "wttc", "thw",
                                           "a0", "omega0", "mean_a", "std_a",
                                           "mean_omega", "std_omega", "n_collisions"},
                          "samples": {"a", "omega", "weight", "ttr", "collision_time",
                                      "evasion"}}]}

        ``samples`` arrays have shape (n_t, N_smp); ``evasion`` holds labels: null (no
        collision), "none" (unavoidable) or manoeuvre names joined by "+".
        """
        objects = []
        for k, oid in enumerate(self.object_ids):
            per = [scene.objects[k] for scene in self.scenes]
            objects.append({
                "id": oid,
                "series": {
                    "risk": [float(o.risk) for o in per],
                    "min_ttr": [_num(o.min_ttr) for o in per],
                    "ttc": [_num(o.ttc) for o in per],
                    "wttc": [_num(o.wttc) for o in per],
                    "thw": [_num(o.thw) for o in per],
                    "a0": [float(o.a0) for o in per],
                    "omega0": [float(o.omega0) for o in per],
                    "mean_a": [float(o.mean_a) for o in per],
                    "std_a": [float(o.std_a) for o in per],
                    "mean_omega": [float(o.mean_omega) for o in per],
                    "std_omega": [float(o.std_omega) for o in per],
                    "n_collisions": [o.n_collisions for o in per],
                },
                "samples": {
                    "a": [[float(v) for v in o.a] for o in per],
                    "omega": [[float(v) for v in o.omega] for o in per],
                    "weight": [[float(v) for v in o.weight] for o in per],
                    "ttr": [_nums(o.ttr) for o in per],
                    "collision_time": [_nums(o.collision_time) for o in per],
                    "evasion": [o.evasion_labels() for o in per],
                },
            })
        return {
            "format": RESULT_FORMAT,
            "settings": self.settings.to_dict(),
            "surfaces": {"source": self.surfaces_source, "interim": self.surfaces_interim},
            "summary": self.summary(),
            "evasion_bits": {m.name: 1 << i for i, m in enumerate(MANOEUVRES)},
            "series": {
                "t": [float(v) for v in self.t],
                "r_dep": [float(s.r_dep) for s in self.scenes],
                "r_ind": [float(s.r_ind) for s in self.scenes],
                "min_ttr": _nums(self.series("min_ttr")),
                "ttc": _nums(self.series("ttc")),
                "wttc": _nums(self.series("wttc")),
                "thw": _nums(self.series("thw")),
            },
            "objects": objects,
        }


def evaluate_scenario(scenario: ConcreteScenario, settings: RiskSettings | None = None,
                      surfaces: InputSurfaces | None = None, *,
                      manoeuvres: tuple[Manoeuvre, ...] | None = None) -> ScenarioRisk:
    """Risk of every scene of a concrete scenario (see the module docstring).

    Parameters
    ----------
    scenario : ConcreteScenario
    settings : RiskSettings, optional
        Table II and the ego's capabilities (defaults when None).
    surfaces : InputSurfaces, optional
        Input distributions (the packaged default when None).
    manoeuvres : tuple of Manoeuvre, optional
        Evasions of the TTR scan (default :data:`riskcore.evasion.MANOEUVRES`).

    Returns
    -------
    ScenarioRisk
    """
    if not isinstance(scenario, ConcreteScenario):
        raise SceneError(f"scenario: expected a ConcreteScenario, got "
                         f"{type(scenario).__name__}")
    s = settings or RiskSettings()
    surf = surfaces or default_surfaces()
    engine = _Engine(s, surf, manoeuvres or MANOEUVRES)
    t = np.asarray(scenario.t, dtype=np.float64)
    for name, track in (("ego", scenario.ego),
                        *((f"objects[{i}]", o) for i, o in enumerate(scenario.objects))):
        if (track.v < 0).any():
            k = int(np.flatnonzero(track.v < 0)[0])
            raise SceneError(f"{name}.v[{k}]: speed must be >= 0, got {track.v[k]}")
    tq = t[:, None] + (np.arange(s.n_steps + 1) * s.dt)[None, :]
    futures = _ego_future(t, scenario.ego, tq,
                          np.asarray(np.unwrap(scenario.ego.psi), dtype=np.float64))
    per_object = []
    for track in scenario.objects:
        a0, w0 = object_inputs(t, track)
        mean_a, std_a = surf.accel(track.v, a0)
        mean_w, std_w = surf.turn(track.v, w0)
        per_object.append((track, a0, w0, mean_a, std_a, mean_w, std_w))
    scenes = []
    for k in range(t.shape[0]):
        ego = futures[k]
        arrays = engine.ego_arrays(ego)
        results = []
        for track, a0, w0, mean_a, std_a, mean_w, std_w in per_object:
            state = ObjectState(id=track.id, x=track.x[k], y=track.y[k], psi=track.psi[k],
                                v=track.v[k], a0=a0[k], omega0=w0[k], length=track.length,
                                width=track.width)
            results.append(engine.object(ego, arrays, state,
                                         (float(mean_a[k]), float(std_a[k]),
                                          float(mean_w[k]), float(std_w[k]))))
        scenes.append(engine.consolidate(tuple(results)))
    return ScenarioRisk(t=t, scenes=tuple(scenes),
                        object_ids=tuple(o.id for o in scenario.objects), settings=s,
                        surfaces_source=surf.source, surfaces_interim=surf.interim)
