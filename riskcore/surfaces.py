"""Input distributions f_a(a | v0, a0) and f_ω(ω | v0, ω0) of eq. (2), as gridded surfaces.

Seed 000, section II-B: the future acceleration a and turn rate ω of a traffic object are
Gaussian, with mean and standard deviation that depend on the object's current speed v0
and current input (a0 or ω0). The surfaces of mean and standard deviation are stored on a
rectangular grid and interpolated bilinearly, clamped at the edges of the grid.

File format (JSON, ``format`` = ``"scengen.input-surfaces/1"``)::

    {"format": "scengen.input-surfaces/1",
     "interim": false,                  # true: hand-made placeholder, not fitted from data
     "source": "text: where it was fitted from",
     "notes": "free text",
     "accel": {"v0": [...],             # m/s, strictly increasing, >= 1 entry
               "x0": [...],             # a0 in m/s^2, strictly increasing, >= 1 entry
               "mean": [[...], ...],    # m/s^2, shape (len(v0), len(x0)), finite
               "std": [[...], ...],     # m/s^2, same shape, finite and > 0
               "count": [[...], ...]},  # optional: samples behind each cell, >= 0
     "turn":  {same keys; x0 is ω0 in rad/s, mean and std in rad/s}}

Unknown keys are an error. ``mean[i][j]`` belongs to ``(v0[i], x0[j])``.

The packaged default lives in ``riskcore/data/input_surfaces.json`` and is what
``InputSurfaces.load(None)`` returns.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore import kernels as _kernels
from riskcore.errors import SurfaceError

__all__ = ["FORMAT", "InputSurfaces", "Surface"]

FORMAT = "scengen.input-surfaces/1"
_TOP_KEYS = frozenset({"format", "interim", "source", "notes", "accel", "turn"})
_SURFACE_KEYS = frozenset({"v0", "x0", "mean", "std", "count"})
_DEFAULT_RESOURCE = "input_surfaces.json"

FloatArray = NDArray[np.float64]


def _axis(value: Any, where: str) -> FloatArray:
    if not isinstance(value, list | tuple | np.ndarray):
        raise SurfaceError(f"{where}: expected a list of numbers, got {type(value).__name__}")
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SurfaceError(f"{where}: expected a list of numbers ({exc})") from None
    if arr.ndim != 1 or arr.shape[0] < 1:
        raise SurfaceError(f"{where}: expected a non-empty flat list of numbers")
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SurfaceError(f"{where}[{i}]: value {float(arr[i])!r} is not a finite number")
    steps = np.diff(arr)
    if (steps <= 0).any():
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise SurfaceError(f"{where}[{i}]: the axis must be strictly increasing")
    return arr


def _table(value: Any, where: str, shape: tuple[int, int]) -> FloatArray:
    if not isinstance(value, list | tuple | np.ndarray):
        raise SurfaceError(f"{where}: expected a list of lists of numbers")
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SurfaceError(f"{where}: expected a rectangular list of lists of numbers ({exc})")\
            from None
    if arr.shape != shape:
        raise SurfaceError(f"{where}: shape {arr.shape} does not match (len(v0), len(x0)) = "
                           f"{shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = (int(k) for k in np.argwhere(bad)[0])
        raise SurfaceError(f"{where}[{i}][{j}]: value {float(arr[i, j])!r} is not a finite number")
    return arr


@dataclass(frozen=True, eq=False)
class Surface:
    """Mean and standard deviation of one input over a (v0, x0) grid.

    Attributes
    ----------
    v0 : ndarray of shape (n_v,)
        Speed axis in m/s, strictly increasing.
    x0 : ndarray of shape (n_x,)
        Current-input axis (a0 in m/s² or ω0 in rad/s), strictly increasing.
    mean, std : ndarray of shape (n_v, n_x)
        Mean and standard deviation of the future input (unit of x0); std > 0.
    count : ndarray of shape (n_v, n_x) or None
        Number of samples behind each cell, when known.
    """

    v0: FloatArray
    x0: FloatArray
    mean: FloatArray
    std: FloatArray
    count: FloatArray | None = None

    def __post_init__(self) -> None:
        checked = Surface.from_dict(self.to_dict(), "surface")
        for name in ("v0", "x0", "mean", "std", "count"):
            object.__setattr__(self, name, getattr(checked, name))

    @classmethod
    def from_dict(cls, data: Any, where: str) -> Surface:
        """Validate and build from the JSON form; errors name ``where.field``."""
        if not isinstance(data, Mapping):
            raise SurfaceError(f"{where}: expected an object, got {type(data).__name__}")
        unknown = sorted(set(data) - _SURFACE_KEYS)
        if unknown:
            raise SurfaceError(f"{where}: unknown field(s) {', '.join(unknown)}")
        for key in ("v0", "x0", "mean", "std"):
            if key not in data:
                raise SurfaceError(f"{where}.{key}: missing")
        v0 = _axis(data["v0"], f"{where}.v0")
        x0 = _axis(data["x0"], f"{where}.x0")
        shape = (v0.shape[0], x0.shape[0])
        mean = _table(data["mean"], f"{where}.mean", shape)
        std = _table(data["std"], f"{where}.std", shape)
        if (std <= 0).any():
            i, j = (int(k) for k in np.argwhere(std <= 0)[0])
            raise SurfaceError(f"{where}.std[{i}][{j}]: must be > 0, got {std[i, j]!r}")
        count = None
        if data.get("count") is not None:
            count = _table(data["count"], f"{where}.count", shape)
            if (count < 0).any():
                i, j = (int(k) for k in np.argwhere(count < 0)[0])
                raise SurfaceError(f"{where}.count[{i}][{j}]: must be >= 0")
        obj = object.__new__(cls)
        for name, value in (("v0", v0), ("x0", x0), ("mean", mean), ("std", std),
                            ("count", count)):
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(obj, name, value)
        return obj

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "v0": [float(v) for v in self.v0],
            "x0": [float(v) for v in self.x0],
            "mean": [[float(v) for v in row] for row in np.asarray(self.mean)],
            "std": [[float(v) for v in row] for row in np.asarray(self.std)],
        }
        if self.count is not None:
            out["count"] = [[float(v) for v in row] for row in np.asarray(self.count)]
        return out

    def __call__(self, v0: ArrayLike, x0: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Bilinear interpolation of (mean, std) at (v0, x0), clamped at the grid edges.

        Parameters
        ----------
        v0 : array-like
            Speed in m/s.
        x0 : array-like
            Current input, broadcastable with ``v0``.

        Returns
        -------
        mean, std : ndarray of the broadcast shape of ``v0`` and ``x0``
        """
        v, x = np.broadcast_arrays(np.asarray(v0, dtype=np.float64),
                                   np.asarray(x0, dtype=np.float64))
        if not (np.isfinite(v).all() and np.isfinite(x).all()):
            raise SurfaceError("surface lookup: v0 and x0 must be finite")
        vf = np.ascontiguousarray(v, dtype=np.float64).ravel()
        xf = np.ascontiguousarray(x, dtype=np.float64).ravel()
        mean = _kernels.bilinear(self.v0, self.x0, self.mean, vf, xf).reshape(v.shape)
        std = _kernels.bilinear(self.v0, self.x0, self.std, vf, xf).reshape(v.shape)
        return mean, std

    def at(self, v0: float, x0: float) -> tuple[float, float]:
        """(mean, std) at one point; the same interpolation as calling the surface."""
        if not (math.isfinite(v0) and math.isfinite(x0)):
            raise SurfaceError("surface lookup: v0 and x0 must be finite")
        m, sd = _kernels.bilinear_pair(self.v0, self.x0, self.mean, self.std, float(v0),
                                       float(x0))
        return float(m), float(sd)

    def mirrored(self) -> Surface:
        """The surface of the mirrored input x → -x: mean(v, -x) → -mean(v, x), same std."""
        return Surface(
            v0=self.v0.copy(),
            x0=-self.x0[::-1],
            mean=-self.mean[:, ::-1],
            std=self.std[:, ::-1].copy(),
            count=None if self.count is None else self.count[:, ::-1].copy(),
        )


@dataclass(frozen=True, eq=False)
class InputSurfaces:
    """The two input distributions of eq. (2): acceleration and turn rate.

    Attributes
    ----------
    accel : Surface
        μ_a(v0, a0) and σ_a(v0, a0) in m/s² over v0 (m/s) and a0 (m/s²). A Surface is
        callable, so ``surfaces.accel(v0, a0)`` returns ``(mean, std)``.
    turn : Surface
        μ_ω(v0, ω0) and σ_ω(v0, ω0) in rad/s over v0 (m/s) and ω0 (rad/s);
        ``surfaces.turn(v0, w0)`` returns ``(mean, std)``.
    interim : bool
        True for a hand-made placeholder that was not fitted from data.
    source, notes : str
        Where the surfaces come from; free text.
    """

    accel: Surface
    turn: Surface
    interim: bool = False
    source: str = ""
    notes: str = ""

    @classmethod
    def from_dict(cls, data: Any, where: str = "surfaces") -> InputSurfaces:
        """Validate and build from the JSON form. Raises SurfaceError naming the field."""
        if not isinstance(data, Mapping):
            raise SurfaceError(f"{where}: expected a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - _TOP_KEYS)
        if unknown:
            raise SurfaceError(f"{where}: unknown field(s) {', '.join(unknown)}")
        fmt = data.get("format")
        if fmt != FORMAT:
            raise SurfaceError(f"{where}.format: expected {FORMAT!r}, got {fmt!r}")
        interim = data.get("interim", False)
        if not isinstance(interim, bool):
            raise SurfaceError(f"{where}.interim: expected true or false")
        texts = {}
        for key in ("source", "notes"):
            value = data.get(key, "")
            if value is None:
                value = ""
            if not isinstance(value, str):
                raise SurfaceError(f"{where}.{key}: expected a string")
            texts[key] = value
        for key in ("accel", "turn"):
            if key not in data:
                raise SurfaceError(f"{where}.{key}: missing")
        return cls(
            accel=Surface.from_dict(data["accel"], f"{where}.accel"),
            turn=Surface.from_dict(data["turn"], f"{where}.turn"),
            interim=interim, source=texts["source"], notes=texts["notes"],
        )

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "interim": bool(self.interim), "source": self.source,
                "notes": self.notes, "accel": self.accel.to_dict(),
                "turn": self.turn.to_dict()}

    @classmethod
    def load(cls, path: str | Path | None = None) -> InputSurfaces:
        """Read a surfaces file; ``None`` reads the packaged default.

        Raises
        ------
        OSError
            The file cannot be read.
        SurfaceError
            The file is not valid JSON or not a valid surfaces object (message names it).
        """
        if path is None:
            text = resources.files("riskcore").joinpath("data", _DEFAULT_RESOURCE).read_text(
                encoding="utf-8")
            where = f"riskcore/data/{_DEFAULT_RESOURCE}"
        else:
            text = Path(path).read_text(encoding="utf-8")
            where = str(path)

        def _reject(token: str) -> float:
            raise SurfaceError(f"{where}: {token} is not valid JSON (numbers must be finite)")

        try:
            data = json.loads(text, parse_constant=_reject)
        except json.JSONDecodeError as exc:
            raise SurfaceError(f"{where}: not valid JSON ({exc})") from None
        return cls.from_dict(data, where)

    def save(self, path: str | Path) -> None:
        """Write the JSON form (plain JSON, no NaN) to ``path``."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n",
                              encoding="utf-8")

    def mirrored(self) -> InputSurfaces:
        """Surfaces of the left/right mirrored world: ω0 → -ω0 gives mean → -mean, same std.

        The acceleration surface is unchanged.
        """
        return InputSurfaces(accel=self.accel, turn=self.turn.mirrored(),
                             interim=self.interim, source=self.source,
                             notes=(self.notes + " [mirrored left/right]").strip())

