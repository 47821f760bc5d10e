"""One scene: the ego's known future and the objects' current states → TTRs and risk.

Seed 000, sections II-III, as DESIGN.md "riskcore" describes:

1. Per object, μ and σ of a and ω from the input surfaces at (v0, a0) and (v0, ω0).
2. The full-factorial grid over ±3σ and its weights p (eq. 4; :mod:`riskcore.sampling`).
3. CTRA rollout of every grid point on the prediction grid t_n = n·dt, n = 0..N
   (:mod:`riskcore.ctra`); oriented-box overlap with the ego's known pose at each step.
4. First collision step c of each predicted trajectory (step 0 included).
5. TTR: for reaction steps j = c-1, c-2, ..., 0 the ego leaves its known trajectory at
   step j with one manoeuvre (:mod:`riskcore.evasion`) for the rest of the horizon; the
   manoeuvre avoids the trajectory when no overlap occurs on steps j+1..N. TTR = j·dt of
   the largest such j, reporting every manoeuvre that works there; +inf without collision;
   0 with evasion "none" when no manoeuvre works from any step (or c = 0).
6. g(TTR) (eq. 5), r_k (eq. 6), r_ind (eq. 9), r_dep (eq. 8, exact); TTC at constant
   velocities, WTTC = earliest collision among the predicted trajectories, THW.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from riskcore import kernels as _kernels
from riskcore.errors import SceneError
from riskcore.evasion import MANOEUVRES, Manoeuvre, evasion_label
from riskcore.risk import risk_dependent, risk_independent
from riskcore.sampling import input_grid
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces

__all__ = ["EgoFuture", "ObjectRisk", "ObjectState", "SceneResult", "evaluate_scene"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_DEFAULT_SURFACES: list[InputSurfaces] = []


def default_surfaces() -> InputSurfaces:
    """The packaged surfaces, read once per process."""
    if not _DEFAULT_SURFACES:
        _DEFAULT_SURFACES.append(InputSurfaces.load(None))
    return _DEFAULT_SURFACES[0]


def _finite(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating |
                                                 np.integer):
        raise SceneError(f"{where}: expected a number, got {type(value).__name__}")
    x = float(value)
    if not math.isfinite(x):
        raise SceneError(f"{where}: must be a finite number, got {value!r}")
    return x


def _size(value: Any, where: str) -> float:
    x = _finite(value, where)
    if x <= 0:
        raise SceneError(f"{where}: must be > 0 m, got {value!r}")
    return x


@dataclass(frozen=True, eq=False)
class EgoFuture:
    """The ego's known future on the prediction grid t_n = n·dt, n = 0..N (n = 0 is now).

    Attributes
    ----------
    x, y : ndarray of shape (N + 1,)
        Centre in m.
    psi : ndarray of shape (N + 1,)
        Heading in rad.
    v : ndarray of shape (N + 1,)
        Speed in m/s (>= 0).
    length, width : float
        Box size in m.
    """

    x: FloatArray
    y: FloatArray
    psi: FloatArray
    v: FloatArray
    length: float = 4.5
    width: float = 1.8

    def __post_init__(self) -> None:
        n = None
        for name in ("x", "y", "psi", "v"):
            arr = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            if arr.ndim != 1 or arr.shape[0] < 2:
                raise SceneError(f"ego.{name}: expected a 1-d array of >= 2 values")
            if n is not None and arr.shape[0] != n:
                raise SceneError(f"ego.{name}: has {arr.shape[0]} values, ego.x has {n}")
            n = arr.shape[0]
            bad = ~np.isfinite(arr)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise SceneError(f"ego.{name}[{i}]: value {arr[i]!r} is not finite")
            object.__setattr__(self, name, arr)
        if (self.v < 0).any():
            i = int(np.flatnonzero(self.v < 0)[0])
            raise SceneError(f"ego.v[{i}]: speed must be >= 0, got {self.v[i]}")
        object.__setattr__(self, "length", _size(self.length, "ego.length"))
        object.__setattr__(self, "width", _size(self.width, "ego.width"))

    @classmethod
    def constant_velocity(cls, x: float, y: float, psi: float, v: float, *,
                          settings: RiskSettings | None = None, length: float = 4.5,
                          width: float = 1.8) -> EgoFuture:
        """A straight future at constant speed and heading from the given state."""
        s = settings or RiskSettings()
        t = np.arange(s.n_steps + 1, dtype=np.float64) * s.dt
        return cls(x=np.asarray(x + v * math.cos(psi) * t, dtype=np.float64),
                   y=np.asarray(y + v * math.sin(psi) * t, dtype=np.float64),
                   psi=np.full(t.shape, float(psi)), v=np.full(t.shape, float(v)),
                   length=length, width=width)


@dataclass(frozen=True)
class ObjectState:
    """A traffic object's current state and inputs (the start of its CTRA prediction).

    Attributes
    ----------
    id : str
    x, y : float
        Centre in m.
    psi : float
        Heading in rad.
    v : float
        Speed in m/s (>= 0).
    a0 : float
        Current acceleration in m/s².
    omega0 : float
        Current turn rate in rad/s.
    length, width : float
        Box size in m.
    """

    id: str
    x: float
    y: float
    psi: float
    v: float
    a0: float = 0.0
    omega0: float = 0.0
    length: float = 4.5
    width: float = 1.8

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id:
            raise SceneError("object.id: expected a non-empty string")
        where = f"objects[{self.id}]"
        for name in ("x", "y", "psi", "v", "a0", "omega0"):
            object.__setattr__(self, name, _finite(getattr(self, name), f"{where}.{name}"))
        if self.v < 0:
            raise SceneError(f"{where}.v: speed must be >= 0, got {self.v}")
        object.__setattr__(self, "length", _size(self.length, f"{where}.length"))
        object.__setattr__(self, "width", _size(self.width, f"{where}.width"))


@dataclass(frozen=True, eq=False)
class ObjectRisk:
    """Result for one object in one scene.

    Attributes
    ----------
    id : str
    risk : float
        r_k of eq. (6) in [0, 1].
    a, omega : ndarray of shape (N_smp,)
        The sampled inputs (m/s², rad/s), point i·n_omega + j = (a_i, ω_j).
    weight : ndarray of shape (N_smp,)
        p of eq. (4), sums to 1.
    ttr : ndarray of shape (N_smp,)
        TTR in s; +inf where the trajectory does not collide; 0 when unavoidable.
    evasion : ndarray of int64, shape (N_smp,)
        Bit mask of the manoeuvres that work at the TTR step (bit m = MANOEUVRES[m]);
        0 when no collision or unavoidable.
    collision_time : ndarray of shape (N_smp,)
        Time of the first overlap with the ego's known trajectory in s; +inf if none.
    g : ndarray of shape (N_smp,)
        g(TTR) of eq. (5).
    ttc, wttc, thw : float
        TTC (constant velocities), WTTC (min of collision_time), THW, in s (+inf: none).
    a0, omega0, mean_a, std_a, mean_omega, std_omega : float
        The object's current inputs and the distributions drawn from the surfaces.
    """

    id: str
    risk: float
    a: FloatArray
    omega: FloatArray
    weight: FloatArray
    ttr: FloatArray
    evasion: IntArray
    collision_time: FloatArray
    g: FloatArray
    ttc: float
    wttc: float
    thw: float
    a0: float
    omega0: float
    mean_a: float
    std_a: float
    mean_omega: float
    std_omega: float

    @property
    def min_ttr(self) -> float:
        """Smallest TTR over the samples (+inf when none collides)."""
        return float(self.ttr.min())

    @property
    def n_collisions(self) -> int:
        return int(np.isfinite(self.collision_time).sum())

    def evasion_labels(self) -> list[str | None]:
        """Per sample: None (no collision), "none" (unavoidable) or the manoeuvre names."""
        collides = np.isfinite(self.collision_time)
        return [evasion_label(int(m), bool(c)) for m, c in zip(self.evasion, collides,
                                                               strict=True)]

    @property
    def min_ttr_evasion(self) -> str | None:
        """Evasion label of the sample with the smallest TTR (ties: the largest weight,
        then the lowest index); None when nothing collides."""
        if not np.isfinite(self.ttr).any():
            return None
        cand = np.flatnonzero(self.ttr == self.ttr.min())
        i = int(cand[np.argmax(self.weight[cand])])
        return evasion_label(int(self.evasion[i]), True)


@dataclass(frozen=True, eq=False)
class SceneResult:
    """Result of one scene: per-object results and the consolidated risks.

    Attributes
    ----------
    objects : tuple of ObjectRisk
    r_ind, r_dep : float
        Eq. (9) and eq. (8); r_dep ≤ r_ind.
    """

    objects: tuple[ObjectRisk, ...]
    r_ind: float
    r_dep: float

    @property
    def risk(self) -> float:
        """The scene risk: r_dep."""
        return self.r_dep

    def _min(self, name: str) -> float:
        return min((float(getattr(o, name)) for o in self.objects), default=math.inf)

    @property
    def min_ttr(self) -> float:
        return self._min("min_ttr")

    @property
    def ttc(self) -> float:
        return self._min("ttc")

    @property
    def wttc(self) -> float:
        return self._min("wttc")

    @property
    def thw(self) -> float:
        return self._min("thw")


@functools.lru_cache(maxsize=64)
def _standard_inputs(n_a: int, n_omega: int, sigma_range: float
                     ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """The grid in standard scores (z_a, z_ω repeated as in input_grid) and its weights."""
    za, zw, weight = input_grid(0.0, 1.0, 0.0, 1.0, n_a, n_omega, sigma_range)
    for arr in (za, zw, weight):
        arr.setflags(write=False)
    return za, zw, weight, float(np.sum(weight))


class _EgoArrays(NamedTuple):
    poses: FloatArray  # (N + 1, 4) known poses [x, y, cos ψ, sin ψ]
    v: FloatArray  # (N + 1,) known speeds
    man_a: FloatArray  # (N, M) manoeuvre accelerations per reaction step
    man_w: FloatArray  # (N, M) manoeuvre turn rates per reaction step
    eva: FloatArray  # (N, M, N + 1, 4) evasive poses, filled on demand
    done: NDArray[np.bool_]  # (N, M) which evasive trajectories are filled


class _Engine:
    """Evaluates scenes with fixed settings, surfaces and manoeuvres (no validation)."""

    def __init__(self, settings: RiskSettings, surfaces: InputSurfaces,
                 manoeuvres: Sequence[Manoeuvre]) -> None:
        if not 1 <= len(manoeuvres) <= 62:
            raise SceneError("manoeuvres: need between 1 and 62 manoeuvres")
        self.settings = settings
        self.surfaces = surfaces
        self.manoeuvres = tuple(manoeuvres)
        # The grid in standard scores and its weights depend on the settings only.
        self._za, self._zw, self._weight, self._weight_sum = _standard_inputs(
            settings.n_a, settings.n_omega, settings.sigma_range)

    def ego_arrays(self, ego: EgoFuture) -> _EgoArrays:
        """Per-scene arrays of the ego: poses, manoeuvre inputs, the evasion buffer."""
        s = self.settings
        n = s.n_steps
        if ego.x.shape[0] != n + 1:
            raise SceneError(f"ego.x: has {ego.x.shape[0]} values, the prediction grid has "
                             f"N + 1 = {n + 1} (horizon {s.horizon} s / dt {s.dt} s)")
        v_react = ego.v[:n]
        n_man = len(self.manoeuvres)
        man_a = np.empty((n, n_man))
        man_w = np.empty((n, n_man))
        for k, man in enumerate(self.manoeuvres):
            a, w = man.inputs(v_react, s)
            man_a[:, k] = a
            man_w[:, k] = w
        poses = _kernels.ego_poses(ego.x, ego.y, ego.psi)
        # evasive trajectories: computed on demand by the scan, shared by all objects
        eva = np.empty((n, n_man, n + 1, 4))
        done = np.zeros((n, n_man), dtype=np.bool_)
        return _EgoArrays(poses, ego.v, man_a, man_w, eva, done)

    def object(self, ego: EgoFuture, arrays: _EgoArrays, obj: ObjectState,
               dist: tuple[float, float, float, float] | None = None) -> ObjectRisk:
        s = self.settings
        if dist is None:
            mean_a, std_a = self.surfaces.accel.at(obj.v, obj.a0)
            mean_w, std_w = self.surfaces.turn.at(obj.v, obj.omega0)
        else:
            mean_a, std_a, mean_w, std_w = dist
        a = mean_a + std_a * self._za
        w = mean_w + std_w * self._zw
        weight = self._weight
        traj = _kernels.predict(obj.x, obj.y, obj.psi, obj.v, a, w, s.n_steps, s.dt)
        first, react, mask = _kernels.ttr_scan(
            traj, 0.5 * obj.length, 0.5 * obj.width, arrays.poses, arrays.v,
            0.5 * ego.length, 0.5 * ego.width, arrays.man_a, arrays.man_w, s.dt, arrays.eva,
            arrays.done)
        ttr, coll_t, g, risk = _kernels.finish(first, react, s.dt, s.t_pnr, s.t_max, s.m,
                                               weight)
        ttc = _kernels.ttc_cv(ego.x[0], ego.y[0], ego.psi[0], ego.length, ego.width, ego.v[0],
                              obj.x, obj.y, obj.psi, obj.length, obj.width, obj.v)
        thw = _kernels.thw_one(ego.x[0], ego.y[0], ego.psi[0], ego.length, ego.width,
                               ego.v[0], obj.x, obj.y, obj.psi, obj.length, obj.width)
        return ObjectRisk(
            id=obj.id, risk=float(risk), a=a, omega=w,
            weight=weight / self._weight_sum, ttr=ttr, evasion=mask, collision_time=coll_t,
            g=g, ttc=float(ttc), wttc=float(coll_t.min()), thw=float(thw), a0=obj.a0,
            omega0=obj.omega0,
            mean_a=mean_a, std_a=std_a, mean_omega=mean_w, std_omega=std_w)

    @staticmethod
    def consolidate(results: tuple[ObjectRisk, ...]) -> SceneResult:
        r_ind = risk_independent([r.risk for r in results])
        if len(results) == 0:
            r_dep = 0.0
        elif len(results) == 1:
            r_dep = results[0].risk  # eq. (8) with one object is eq. (6)
        else:
            r_dep = risk_dependent(np.stack([r.g for r in results]),
                                   np.stack([r.weight for r in results]))
        return SceneResult(objects=results, r_ind=r_ind, r_dep=r_dep)


def evaluate_scene(ego: EgoFuture, objects: Sequence[ObjectState],
                   settings: RiskSettings | None = None,
                   surfaces: InputSurfaces | None = None, *,
                   manoeuvres: Sequence[Manoeuvre] | None = None) -> SceneResult:
    """Risk of one scene (seed 000, sections II-III).

    Parameters
    ----------
    ego : EgoFuture
        The ego's known future, N + 1 = horizon / dt + 1 points from now.
    objects : sequence of ObjectState
        The traffic objects' current states (ids unique).
    settings : RiskSettings, optional
        Table II and the ego's capabilities (defaults when None).
    surfaces : InputSurfaces, optional
        Input distributions (the packaged default when None).
    manoeuvres : sequence of Manoeuvre, optional
        The evasions tried by the TTR scan (default :data:`riskcore.evasion.MANOEUVRES`).

    Returns
    -------
    SceneResult
    """
    if not isinstance(ego, EgoFuture):
        raise SceneError(f"ego: expected an EgoFuture, got {type(ego).__name__}")
    objs = tuple(objects)
    for k, obj in enumerate(objs):
        if not isinstance(obj, ObjectState):
            raise SceneError(f"objects[{k}]: expected an ObjectState, got "
                             f"{type(obj).__name__}")
    ids = [o.id for o in objs]
    if len(set(ids)) != len(ids):
        raise SceneError("objects: ids must be unique")
    engine = _Engine(settings or RiskSettings(), surfaces or default_surfaces(),
                     manoeuvres or MANOEUVRES)
    arrays = engine.ego_arrays(ego)
    results = tuple(engine.object(ego, arrays, o) for o in objs)
    return engine.consolidate(results)

