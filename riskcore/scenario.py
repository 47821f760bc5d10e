"""Concrete scenario: time series of the ego and the other objects on one time grid.

This is the interchange type of scengen (DESIGN.md, "Concrete scenario"). It is pure data:
numpy arrays plus the parameter vector, seed and provenance it came from. ``to_dict`` and
``from_dict`` give its JSON form (plain lists and numbers); the round trip is lossless
because floats go through Python ``float`` (IEEE double, printed by ``json`` with repr).

JSON form (``schema`` = ``"scengen.concrete-scenario/1"``)::

    {
      "schema": "scengen.concrete-scenario/1",
      "t": [0.0, 0.1, ...],                     # s, strictly increasing, >= 2 entries
      "ego": {"id": "ego", "length": 4.5, "width": 1.8,         # m, > 0
              "x": [...], "y": [...], "psi": [...], "v": [...],  # m, m, rad, m/s
              "a": [...] | null, "yaw_rate": [...] | null},      # m/s^2, rad/s (optional)
      "objects": [ {same keys as ego}, ... ],                    # ids unique, != ego's
      "params": {"p_y1": ..., ...},            # parameter vector it came from (may be {})
      "seed": 1 | null,
      "provenance": {...}                      # free-form JSON object
    }

Every series has the length of ``t``; every number is finite. Unknown keys are an error.
Road frame: x along the road in the driving direction, y to the left, psi counter-clockwise
from +x; positions are vehicle centres.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riskcore.errors import RiskcoreError

SCHEMA = "scengen.concrete-scenario/1"
_SERIES = ("x", "y", "psi", "v")
_OPTIONAL_SERIES = ("a", "yaw_rate")
_TRACK_KEYS = frozenset({"id", "length", "width", *_SERIES, *_OPTIONAL_SERIES})
_TOP_KEYS = frozenset({"schema", "t", "ego", "objects", "params", "seed", "provenance"})

FloatArray = NDArray[np.float64]


class ScenarioError(RiskcoreError):
    """A concrete scenario is malformed. The message names the field and the problem.

    A ``ValueError`` (through :class:`riskcore.errors.RiskcoreError`)."""


def _as_series(value: Any, where: str, n: int | None) -> FloatArray:
    if not isinstance(value, list | tuple | np.ndarray):
        raise ScenarioError(f"{where}: expected a list of numbers, got {type(value).__name__}",
                            field=where)
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{where}: expected a list of numbers ({exc})", field=where) from None
    if arr.ndim != 1:
        raise ScenarioError(f"{where}: expected a flat list of numbers, got shape {arr.shape}",
                            field=where)
    if n is not None and arr.shape[0] != n:
        raise ScenarioError(f"{where}: has {arr.shape[0]} values but t has {n} (ragged series)",
                            field=where)
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ScenarioError(f"{where}[{i}]: value {float(arr[i])!r} is not a finite number",
                            field=f"{where}[{i}]")
    return arr


def _as_positive(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ScenarioError(f"{where}: expected a number, got {type(value).__name__}", field=where)
    x = float(value)
    if not math.isfinite(x) or x <= 0.0:
        raise ScenarioError(f"{where}: must be a positive finite number of metres, got {value!r}",
                            field=where)
    return x


@dataclass(frozen=True, eq=False)
class Track:
    """One vehicle's motion. Arrays have shape (n_t,), SI units, road frame, centre point.

    Attributes
    ----------
    id : str
    length, width : float
        Bounding-box size in m (length along the heading).
    x, y : ndarray of shape (n_t,)
        Centre position in m.
    psi : ndarray of shape (n_t,)
        Heading in rad, counter-clockwise from +x.
    v : ndarray of shape (n_t,)
        Speed along the heading in m/s.
    a, yaw_rate : ndarray of shape (n_t,) or None
        Longitudinal acceleration (m/s^2) and yaw rate (rad/s) when known.
    """

    id: str
    length: float
    width: float
    x: FloatArray
    y: FloatArray
    psi: FloatArray
    v: FloatArray
    a: FloatArray | None = None
    yaw_rate: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "length": float(self.length),
                               "width": float(self.width)}
        for key in _SERIES:
            out[key] = [float(v) for v in getattr(self, key)]
        for key in _OPTIONAL_SERIES:
            arr = getattr(self, key)
            out[key] = None if arr is None else [float(v) for v in arr]
        return out

    @classmethod
    def from_dict(cls, data: Any, where: str, n: int) -> Track:
        if not isinstance(data, Mapping):
            raise ScenarioError(f"{where}: expected an object, got {type(data).__name__}",
                                field=where)
        unknown = sorted(set(data) - _TRACK_KEYS)
        if unknown:
            raise ScenarioError(f"{where}: unknown field(s) {', '.join(unknown)}", field=where)
        for key in ("id", "length", "width", *_SERIES):
            if key not in data:
                raise ScenarioError(f"{where}.{key}: missing", field=f"{where}.{key}")
        if not isinstance(data["id"], str) or not data["id"]:
            raise ScenarioError(f"{where}.id: expected a non-empty string", field=f"{where}.id")
        series = {key: _as_series(data[key], f"{where}.{key}", n) for key in _SERIES}
        optional = {
            key: None if data.get(key) is None else _as_series(data[key], f"{where}.{key}", n)
            for key in _OPTIONAL_SERIES
        }
        return cls(
            id=data["id"],
            length=_as_positive(data["length"], f"{where}.length"),
            width=_as_positive(data["width"], f"{where}.width"),
            x=series["x"], y=series["y"], psi=series["psi"], v=series["v"],
            a=optional["a"], yaw_rate=optional["yaw_rate"],
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Track):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class ConcreteScenario:
    """Ego and other objects on one time grid ``t`` (s), plus where the scenario came from."""

    t: FloatArray
    ego: Track
    objects: tuple[Track, ...]
    params: dict[str, float] = field(default_factory=dict)
    seed: int | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Validate through the same path as JSON input, so both entry points agree (the
        # arrays as they are: the JSON path takes arrays as well as lists, and converting
        # every value to a Python float first cost a millisecond per built scenario)
        ConcreteScenario.from_dict(self._arrays_dict())

    def _arrays_dict(self) -> dict[str, Any]:
        """``to_dict`` with the series left as arrays (for validation)."""

        def track(tr: Track) -> dict[str, Any]:
            out: dict[str, Any] = {"id": tr.id, "length": tr.length, "width": tr.width}
            for key in (*_SERIES, *_OPTIONAL_SERIES):
                out[key] = getattr(tr, key)
            return out

        return {"schema": SCHEMA, "t": self.t, "ego": track(self.ego),
                "objects": [track(o) for o in self.objects], "params": self.params,
                "seed": self.seed, "provenance": self.provenance}

    @property
    def dt(self) -> float:
        """Median time step in s."""
        return float(np.median(np.diff(self.t)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "t": [float(v) for v in self.t],
            "ego": self.ego.to_dict(),
            "objects": [obj.to_dict() for obj in self.objects],
            "params": {str(k): float(v) for k, v in self.params.items()},
            "seed": self.seed,
            "provenance": dict(self.provenance),
        }

    @classmethod
    def from_dict(cls, data: Any) -> ConcreteScenario:
        """Validate and build from the JSON form. Raises ScenarioError naming the field."""
        if not isinstance(data, Mapping):
            raise ScenarioError(f"scenario: expected a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - _TOP_KEYS)
        if unknown:
            raise ScenarioError(f"scenario: unknown field(s) {', '.join(unknown)}")
        schema = data.get("schema", SCHEMA)
        if schema != SCHEMA:
            raise ScenarioError(f"schema: expected {SCHEMA!r}, got {schema!r}", field="schema")
        if "t" not in data:
            raise ScenarioError("t: missing", field="t")
        t = _as_series(data["t"], "t", None)
        if t.shape[0] < 2:
            raise ScenarioError("t: needs at least 2 time steps", field="t")
        steps = np.diff(t)
        if (steps <= 0).any():
            i = int(np.flatnonzero(steps <= 0)[0]) + 1
            raise ScenarioError(f"t[{i}]: time must be strictly increasing ({t[i - 1]} -> {t[i]})",
                                field=f"t[{i}]")
        n = t.shape[0]
        if "ego" not in data:
            raise ScenarioError("ego: missing", field="ego")
        ego = Track.from_dict(data["ego"], "ego", n)
        raw_objects = data.get("objects", [])
        if not isinstance(raw_objects, list):
            raise ScenarioError("objects: expected a list", field="objects")
        objects = tuple(
            Track.from_dict(obj, f"objects[{i}]", n) for i, obj in enumerate(raw_objects)
        )
        ids = [ego.id] + [o.id for o in objects]
        if len(set(ids)) != len(ids):
            raise ScenarioError("objects: ids must be unique and differ from the ego's",
                                field="objects")
        params_raw = data.get("params") or {}
        if not isinstance(params_raw, Mapping):
            raise ScenarioError("params: expected an object of numbers", field="params")
        params: dict[str, float] = {}
        for key, value in params_raw.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ScenarioError(f"params.{key}: expected a number", field=f"params.{key}")
            if not math.isfinite(value):
                raise ScenarioError(f"params.{key}: value {value!r} is not a finite number",
                                    field=f"params.{key}")
            params[str(key)] = float(value)
        seed = data.get("seed")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
            raise ScenarioError("seed: expected an integer or null", field="seed")
        provenance = data.get("provenance") or {}
        if not isinstance(provenance, Mapping):
            raise ScenarioError("provenance: expected an object", field="provenance")
        obj = object.__new__(cls)
        for name, value in (("t", t), ("ego", ego), ("objects", objects), ("params", params),
                            ("seed", seed), ("provenance", dict(provenance))):
            object.__setattr__(obj, name, value)
        return obj

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ConcreteScenario):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]
