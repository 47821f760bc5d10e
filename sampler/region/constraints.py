"""Constraints as data: which part of the parameter space a sample set lives in.

A constraint is ``{"name": "ttc", "op": "<", "value": 3}``: a *quantity* compared with a
number. Quantities are the cut-in parameters (``PARAM_NAMES``) and derived quantities
(``DERIVED``), all computed vectorised for an array of parameter vectors. A ``Region`` is
the conjunction of its constraints and, unless switched off, the physical bounds
``PHYSICAL_BOUNDS`` (the vectors a real car could drive: positive speeds, positive gap,
non-negative durations, a lane change that actually crosses the marking).

Derived quantities (road frame, SI units; the motion is described from ``t = 0``, the start
of the lateral motion, but the two moments ``t_cross`` and ``t_p`` are reported in scenario
time, as in the built scenario: t = 0 at its first sample, the lateral motion starting at
the builder's lead-in of 2.5 s)::

    ttc           s    gap / dv at the crossing moment if dv > 0, else +inf
    t_cross       s    crossing moment: first t with |y(t)| = lane_width / 2 (NaN if never),
                       in *scenario time* like t_p: the built scenario's lead-in (2.5 s)
                       plus the time from the start of the lateral motion
    v_cross       m/s  cutter speed at t_cross
    v_ego         m/s  ego speed = v_cross + dv (the ego drives at constant speed)
    thw           s    gap / v_ego (+inf if v_ego <= 0)
    lat_disp      m    |y(2 p_t)|, the lateral distance covered by the lane change
    cross_margin  m    lat_disp - lane_width / 2 (> 0: the marking is crossed)
    lat_offset    m    final lateral offset of the cutter from the ego-lane centre, + left:
                       -sign(p_y1) lane_width + y(2 p_t) (it starts in the adjacent lane)
    end_margin    m    lane_width / 2 - |lat_offset| (> 0: the cutter ends inside the ego
                       lane instead of running on across its far marking)
    direction     -    +1 if the cutter moves left (p_y1 > 0, starts on the right), else -1
    psi_max       rad  peak heading 2 |p_y1| p_t / pi
    v_cut_min     m/s  the cutter's lowest speed at any time (before or after the pulse)
    max_lat_speed m/s  the largest lateral speed |v sin psi| during the lane change
    btn_bound     -    an upper bound of btn proved from the motion alone, without the
                       simulation (``sampler.region.btn_bound``; never below btn)

Criticality quantities (``sampler.region.criticality``; the values ``evaluate_criticality`` gives
the built scenario; evaluated last, on the rows that pass every other constraint)::

    t_p               s     perception moment, *scenario* time (lead-in 2.5 s included)
    a_req             m/s2  deceleration needed from t_p + 0.75 s (0: none; inf: too late)
    btn               -     a_req / (0.774 g)
    ttr_true          s     TTR at t_p on the cutter's actual path (inf: no collision)
    r157_collision    -     1 if the UN R157 careful driver hits the cutter, else 0
    r157_impact_speed m/s   its relative impact speed (0 without contact)
    none_collision    -     1 if the ego at constant speed hits the cutter, else 0

A lower limit on ``btn`` or ``a_req`` (``btn > 0.4``, ``a_req >= 3``) implies the same limit
on ``btn_bound``, which costs no simulation: ``Region`` checks it first (right after the
cheap constraints, before the crossing kinematics), so only the vectors whose bound reaches
the limit are simulated. The rows inside are the same; only the cost changes.

Model quantities (``sampler.model.support``; need the model, which ``sample`` and
``estimate_p_region`` bind to the region: ``Region.bind``)::

    density_pct       -     share of the model's physical cut-ins less probable than this
                            one (0: beyond every reference draw; caps extrapolation)
    support           -     data support class: 0 inside, 1 near, 2 extrapolated; also
                            written with words: support!=extrapolated, support==inside,
                            support<=near
    support_distance  -     distance to the nearest real cut-in of the training data in the
                            model's standardised transformed space
    support_excess    sd    largest excess of a parameter beyond the training data's range,
                            in the data's standard deviations (0: inside every range)

Model quantities are evaluated after the cheap constraints, on the rows still inside.

Short form (CLI): ``ttc<3``, ``v_ego>=20``, ``lat_offset > -0.5`` — a name, one of the
operators ``< <= > >=`` and a finite number, parsed by a regular expression (never eval).
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_validator,
)

from datasets import DEFAULT_LANE_WIDTH, PARAM_NAMES, ttc_from_gap_dv
from riskcore.criticality import CriticalitySettings
from sampler.errors import ConstraintError
from sampler.region.btn_bound import btn_bound
from sampler.region.criticality import CRITICALITY_QUANTITIES, criticality_quantities
from sampler.region.kinematics import crossing_kinematics, plateau_speeds
from sampler.scenario.builder import DEFAULT_LEAD_IN

__all__ = [
    "DERIVED",
    "NUMBER_PATTERN",
    "OPERATORS",
    "PHYSICAL_BOUNDS",
    "QUANTITY_NAMES",
    "SUPPORT_CLASSES",
    "Constraint",
    "Region",
    "constraint_grammar",
    "constraint_pattern",
    "derive",
    "implied_bounds",
    "parse_constraint",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

OPERATORS: dict[str, Callable[[FloatArray, float], BoolArray]] = {
    "<": np.less,
    "<=": np.less_equal,
    ">": np.greater,
    ">=": np.greater_equal,
}


@dataclass(frozen=True)
class _Quantity:
    unit: str
    doc: str
    kinematic: bool  # needs the crossing kinematics (costly: evaluated late, on survivors)
    criticality: bool = False  # a closed-loop simulation (costliest: evaluated last)
    model: bool = False  # needs the model (Region.bind): its density


#: Derived quantities: name -> unit, meaning, whether the kinematics are needed.
DERIVED: dict[str, _Quantity] = {
    "ttc": _Quantity("s", "gap / dv at the crossing moment if dv > 0, else +inf", False),
    "direction": _Quantity("-", "+1 if the cutter moves left (p_y1 > 0), else -1", False),
    "psi_max": _Quantity("rad", "peak heading 2 |p_y1| p_t / pi", False),
    "v_cut_min": _Quantity("m/s", "the cutter's lowest speed at any time", False),
    "t_cross": _Quantity("s", "crossing moment (|y| = lane_width / 2), scenario time (lead-in "
                         "2.5 s included, like t_p)", True),
    "v_cross": _Quantity("m/s", "cutter speed at the crossing moment", True),
    "v_ego": _Quantity("m/s", "ego speed = v_cross + dv", True),
    "thw": _Quantity("s", "gap / v_ego at the crossing moment", True),
    "lat_disp": _Quantity("m", "lateral distance covered by the lane change", True),
    "cross_margin": _Quantity("m", "lat_disp - lane_width / 2 (> 0: marking crossed)", True),
    "lat_offset": _Quantity("m", "final offset of the cutter from the ego-lane centre", True),
    "end_margin": _Quantity("m", "lane_width / 2 - |lat_offset| (> 0: ends in the ego lane)",
                            True),
    "max_lat_speed": _Quantity("m/s", "largest lateral speed during the lane change", True),
    "btn_bound": _Quantity("-", "an upper bound of btn proved from the motion alone, without "
                           "the simulation (never below btn)", True),
    **{name: _Quantity(unit, doc, True, True)
       for name, (unit, doc) in CRITICALITY_QUANTITIES.items()},
    "density_pct": _Quantity("-", "share of the model's physical cut-ins less probable than "
                             "this one (sampler.model.support)", False, model=True),
    "support": _Quantity("-", "data support class: 0 inside, 1 near, 2 extrapolated; words "
                         "allowed: support!=extrapolated, support==inside "
                         "(sampler.model.support)", False, model=True),
    "support_distance": _Quantity("-", "distance to the nearest real cut-in of the training "
                                  "data in the model's standardised space "
                                  "(sampler.model.support)", False, model=True),
    "support_excess": _Quantity("sd", "largest excess of a parameter beyond the training "
                                "data's range, in the data's standard deviations (0: inside "
                                "every range)", False, model=True),
}

#: the data-support classes in order (``sampler.model.support.CLASSES``): a vector's
#: ``support`` value is its position
SUPPORT_CLASSES: tuple[str, ...] = ("inside", "near", "extrapolated")
_SUPPORT_NAMES = ("support", "support_distance", "support_excess")

#: Every name a constraint may use.
QUANTITY_NAMES: tuple[str, ...] = (*PARAM_NAMES, *DERIVED)

#: how a constraint's number is written: ASCII digits, an optional sign, decimal point and
#: exponent (``3``, ``-0.5``, ``.5``, ``1e-3``); Python's ``float`` would also take
#: ``３`` (a fullwidth digit), ``1_000``, ``inf`` and ``nan``, which a constraint does not
NUMBER_PATTERN = r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
_NUMBER = re.compile(NUMBER_PATTERN)


def constraint_grammar() -> str:
    """One constraint as a regular expression without anchors or surrounding blanks: a
    quantity, one of ``< <= > >=`` and a number (``NUMBER_PATTERN``), or ``support``
    compared with a class (its word checked by the parser)."""
    names = "|".join(sorted((n for n in QUANTITY_NAMES if n != "support"), key=len,
                            reverse=True))
    return (rf"(?:(?:{names})\s*(?:<=|>=|<|>)\s*{NUMBER_PATTERN}"
            rf"|support\s*(?:<=|>=|==|!=|=<|=>|<|>|=)\s*\S+)")


def constraint_pattern() -> str:
    """The short form's grammar as one anchored regular expression (the API's JSON schema
    uses it). Every text it refuses, ``parse_constraint`` refuses too."""
    return rf"^\s*{constraint_grammar()}\s*$"


class Constraint(BaseModel):
    """One comparison ``quantity op value``; JSON ``{"name": "ttc", "op": "<", "value": 3}``."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(description="a parameter or derived quantity (see QUANTITY_NAMES)")
    op: str = Field(description="one of < <= > >=")
    value: float = Field(description="threshold in the quantity's SI unit; finite")

    @model_validator(mode="before")
    @classmethod
    def _support_words(cls, data: Any) -> Any:
        """``{"name": "support", "op": "!=", "value": "extrapolated"}`` in JSON too; every
        support constraint in one form (``<=`` or ``>=`` a class code), so that equal sets
        are equal constraints."""
        if isinstance(data, Mapping) and data.get("name") == "support":
            op, value = _support_comparison(str(data.get("op")), str(data.get("value")),
                                            f"support{data.get('op')}{data.get('value')}")
            return {**data, "op": op, "value": value}
        return data

    @field_validator("name")
    @classmethod
    def _known_name(cls, v: str) -> str:
        if v not in QUANTITY_NAMES:
            raise ValueError(f"unknown quantity {v!r}{did_you_mean(v)}; valid names: "
                             f"{', '.join(QUANTITY_NAMES)}")
        return v

    @field_validator("op")
    @classmethod
    def _known_op(cls, v: str) -> str:
        if v not in OPERATORS:
            raise ValueError(f"unknown operator {v!r}; valid operators: {' '.join(OPERATORS)}")
        return v

    @field_validator("value")
    @classmethod
    def _finite(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"value must be a finite number, got {v!r}")
        return v

    @property
    def is_kinematic(self) -> bool:
        """True when evaluating this constraint needs the crossing kinematics."""
        return self.name in DERIVED and DERIVED[self.name].kinematic

    @property
    def tier(self) -> int:
        """Evaluation order: 0 cheap, 1 kinematic, 2 criticality (closed-loop runs)."""
        q = DERIVED.get(self.name)
        if q is None or not q.kinematic:
            return 0
        return 2 if q.criticality else 1

    @property
    def needs_model(self) -> bool:
        """True for the model quantities (``density_pct``, ``support``, ...)."""
        q = DERIVED.get(self.name)
        return q is not None and q.model

    def __str__(self) -> str:
        if self.name == "support":
            allowed = tuple(k for k in range(len(SUPPORT_CLASSES))
                            if bool(OPERATORS[self.op](np.full(1, float(k)), self.value)[0]))
            words = {(0,): "==inside", (0, 1): "!=extrapolated", (1, 2): "!=inside",
                     (2,): "==extrapolated"}
            if allowed in words:
                return f"support{words[allowed]}"
        return f"{self.name}{self.op}{self.value:g}"

    def mask(self, values: FloatArray) -> BoolArray:
        """Rows of ``values`` (the quantity, shape (n,)) that satisfy the constraint."""
        return np.asarray(OPERATORS[self.op](values, self.value), dtype=bool)


#: The physical bounds every sample of a bounded region satisfies.
PHYSICAL_BOUNDS: tuple[Constraint, ...] = (
    Constraint(name="p_t", op=">", value=0.0),           # a lane change takes time
    Constraint(name="p_a3", op=">=", value=0.0),         # durations are non-negative
    Constraint(name="p_v0", op=">", value=0.0),          # the cutter drives forwards ...
    Constraint(name="v_cut_min", op=">", value=0.0),     # ... at every moment
    Constraint(name="gap", op=">", value=0.0),           # the cutter is ahead of the ego
    Constraint(name="psi_max", op="<", value=math.pi / 2),  # never turns sideways
    Constraint(name="cross_margin", op=">", value=0.0),  # the marking is crossed ...
    Constraint(name="end_margin", op=">", value=0.0),    # ... and only that one marking
    Constraint(name="v_ego", op=">", value=0.0),         # the ego drives forwards
)

_SHORT = re.compile(
    r"^\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*(?P<op><=|>=|<|>|==|=<|=>|!=|=)\s*(?P<value>\S+)\s*$"
)


def did_you_mean(name: str) -> str:
    """``"; did you mean 'ttc'?"`` for a name close to a quantity's, else ``""``."""
    close = difflib.get_close_matches(name, QUANTITY_NAMES, n=3, cutoff=0.6)
    if not close:
        close = [q for q in QUANTITY_NAMES if q.lower() == name.lower()]
    if not close:
        return ""
    return "; did you mean " + " or ".join(repr(c) for c in close) + "?"


def _support_comparison(op: str, raw: str, text: str) -> tuple[str, float]:
    """``support`` compared with a class word (or ``==``/``!=`` a class) as one of the
    four operators on the class codes (0 inside, 1 near, 2 extrapolated)."""
    word = raw.strip().strip("'\"").lower()
    last = len(SUPPORT_CLASSES) - 1
    if word in SUPPORT_CLASSES:
        k = SUPPORT_CLASSES.index(word)
    else:
        try:
            k = int(float(word))
        except (ValueError, OverflowError):
            raise ConstraintError(
                f"constraint {text!r}: support is one of {', '.join(SUPPORT_CLASSES)}, got "
                f"{raw!r}", field="value", problem="unknown class", value=raw,
                constraint=text) from None
        if k not in range(len(SUPPORT_CLASSES)) or float(word) != k:
            raise ConstraintError(
                f"constraint {text!r}: support is one of {', '.join(SUPPORT_CLASSES)} "
                f"(0, 1, 2), got {raw!r}", field="value", problem="unknown class",
                value=raw, constraint=text)
    if op == "<":
        return "<=", float(k - 1)
    if op == ">":
        return ">=", float(k + 1)
    if op in ("<=", ">="):
        return op, float(k)
    if op in ("==", "="):
        if k == 0:
            return "<=", 0.0
        if k == last:
            return ">=", float(last)
    elif op == "!=":
        if k == 0:
            return ">=", 1.0
        if k == last:
            return "<=", float(last - 1)
    else:
        raise ConstraintError(f"constraint {text!r}: unknown operator {op!r}; valid "
                              f"operators: {' '.join(OPERATORS)} == !=", field="op",
                              problem="unknown operator", value=op, constraint=text)
    raise ConstraintError(
        f"constraint {text!r}: 'near' lies between the other two classes; use "
        "'support>=near' and 'support<=near' (two constraints) for support==near, or "
        "'support!=extrapolated' / 'support!=inside'", field="value",
        problem="not one comparison", value=raw, constraint=text)


def parse_constraint(text: str) -> Constraint:
    """Parse the short form ``name op value`` (e.g. ``"ttc<3"``, ``"v_ego >= 20"``).

    Raises
    ------
    ConstraintError
        Malformed text, unknown name or operator, or a value that is not a finite number;
        the message lists the valid names or operators.
    """
    if not isinstance(text, str):
        raise ConstraintError(f"constraint: expected text like 'ttc<3', got {type(text).__name__}",
                              problem="not text", value=text)
    m = _SHORT.match(text)
    if m is None:
        raise ConstraintError(
            f"constraint {text!r}: expected NAME OP VALUE such as 'ttc<3' "
            f"(operators: {' '.join(OPERATORS)})", problem="malformed", value=text,
            constraint=text)
    name, op, raw = m.group("name"), m.group("op"), m.group("value")
    if name == "support":
        op_s, value_s = _support_comparison(op, raw, text)
        return Constraint(name=name, op=op_s, value=value_s)
    if op not in OPERATORS:
        raise ConstraintError(
            f"constraint {text!r}: unknown operator {op!r}; valid operators: {' '.join(OPERATORS)}",
            field="op", problem="unknown operator", value=op, constraint=text)
    if name not in QUANTITY_NAMES:
        raise ConstraintError(
            f"constraint {text!r}: unknown quantity {name!r}{did_you_mean(name)} (valid "
            f"names: {', '.join(QUANTITY_NAMES)})", field="name", problem="unknown quantity",
            value=name, constraint=text)
    if _NUMBER.fullmatch(raw) is None and raw.lstrip("+-").lower() not in (
            "inf", "infinity", "nan"):  # those: "must be finite" below
        why = ("is not written with ASCII digits" if not raw.isascii()
               else "is not a number such as 3, -0.5 or 1e-3")
        raise ConstraintError(f"constraint {text!r}: value {raw!r} {why}",
                              field="value", problem="not a number", value=raw,
                              constraint=text)
    value = float(raw)
    if not math.isfinite(value):
        raise ConstraintError(f"constraint {text!r}: value must be finite, got {raw!r}",
                              field="value", problem="not finite", value=raw, constraint=text)
    return Constraint(name=name, op=op, value=value)


def _as_constraint(c: Any) -> Constraint:
    if isinstance(c, Constraint):
        return c
    if isinstance(c, str):
        return parse_constraint(c)
    if isinstance(c, Mapping):
        try:
            return Constraint.model_validate(c)
        except ValidationError as exc:
            errors = exc.errors()
            loc = ".".join(str(x) for x in errors[0]["loc"]) or None if errors else None
            raise ConstraintError(_pydantic_message(exc), field=loc, problem="invalid",
                                  value=errors[0]["input"] if errors else None,
                                  constraint=str(dict(c))) from None
    raise ConstraintError(f"constraint: expected text, a mapping or Constraint, got {c!r}",
                          problem="not a constraint", value=c)


def _pydantic_message(exc: Exception) -> str:
    errors = getattr(exc, "errors", None)
    if callable(errors):
        parts = []
        for err in errors():
            loc = ".".join(str(x) for x in err.get("loc", ()))
            msg = str(err.get("msg", "")).removeprefix("Value error, ")
            parts.append(f"{loc}: {msg}" if loc else msg)
        return "constraint: " + "; ".join(parts)
    return f"constraint: {exc}"


def _params_matrix(params: ArrayLike | Mapping[str, ArrayLike]) -> FloatArray:
    """Accept (n, 8) arrays in PARAM_NAMES order, or a mapping/DataFrame of columns."""
    if isinstance(params, Mapping) or hasattr(params, "columns"):
        cols: Any = params  # DataFrame or mapping
        missing = [k for k in PARAM_NAMES if k not in cols]
        if missing:
            raise ConstraintError(f"params: missing column(s) {', '.join(missing)}",
                                  field="params", problem="missing columns", value=missing)
        arr = np.column_stack([np.asarray(cols[k], dtype=np.float64).reshape(-1)
                               for k in PARAM_NAMES])
    else:
        arr = np.asarray(params, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != len(PARAM_NAMES):
        raise ConstraintError(
            f"params: expected shape (n, {len(PARAM_NAMES)}) in the order {PARAM_NAMES}, "
            f"got {arr.shape}", field="params", problem="wrong shape", value=arr.shape)
    return arr


class _Quantities:
    """Lazy, cached evaluation of parameters and derived quantities for rows of a matrix."""

    def __init__(self, params: FloatArray, lane_width: float, model: Any = None,
                 bound_stop_at: float = 0.0) -> None:
        self.p = params
        self.lane_width = lane_width
        self.model = model
        # btn_bound: only whether it reaches this matters (a looser bound below it is
        # cheaper; sampler.region.btn_bound)
        self.bound_stop_at = bound_stop_at
        self._cache: dict[str, FloatArray] = {}

    def __getitem__(self, name: str) -> FloatArray:
        if name in self._cache:
            return self._cache[name]
        if name in PARAM_NAMES:
            return self.p[:, PARAM_NAMES.index(name)]
        col = {k: self.p[:, i] for i, k in enumerate(PARAM_NAMES)}
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if name in ("ttc", "direction", "psi_max", "v_cut_min", "btn_bound"):
                self._cache[name] = self._closed_form(name, col)
            elif name in CRITICALITY_QUANTITIES:
                self._criticality(name)
            elif name == "density_pct" or name in _SUPPORT_NAMES:
                self._support(name)
            elif name in DERIVED:
                self._crossing(col)
            else:
                raise ConstraintError(
                    f"unknown quantity {name!r}; valid names: {', '.join(QUANTITY_NAMES)}"
                )
        return self._cache[name]

    def _closed_form(self, name: str, col: dict[str, FloatArray]) -> FloatArray:
        """A quantity with a formula of its own (``btn_bound``: sampler.region.btn_bound)."""
        if name == "ttc":
            return ttc_from_gap_dv(col["gap"], col["dv"])
        if name == "direction":
            return np.where(col["p_y1"] > 0, 1.0, -1.0)
        if name == "psi_max":
            return 2.0 * np.abs(col["p_y1"]) * col["p_t"] / np.pi
        if name == "v_cut_min":
            before, after = plateau_speeds(col["p_a1"], col["p_a2"], col["p_a3"], col["p_v0"])
            return np.minimum(before, after)
        return btn_bound(self.p, self.lane_width, stop_at=self.bound_stop_at)

    def _criticality(self, name: str) -> None:
        """The criticality quantities into the cache (sampler.region.criticality)."""
        # the TTR scan costs more than the drivers: only when ttr_true is asked for
        q = criticality_quantities(self.p, self.lane_width, with_ttr=name == "ttr_true")
        if name != "ttr_true":
            del q["ttr_true"]
        self._cache.update(q)

    def _support(self, name: str) -> None:
        """``density_pct`` or the support measures into the cache, from the model."""
        if self.model is None:
            raise ConstraintError(f"{name} needs the model: use sample() or "
                                  "estimate_p_region(), or Region.bind(model)")
        # the model knows its own support (sampler.model.support); the region only
        # asks it, so that this layer does not import the model's
        c = self._cache
        if name == "density_pct":
            c[name] = np.asarray(self.model.density_percentile(self.p), dtype=np.float64)
        else:
            sm = self.model.support_measures(self.p)
            c["support"] = np.asarray(sm.code, dtype=np.float64)
            c["support_distance"] = np.asarray(sm.distance, dtype=np.float64)
            c["support_excess"] = np.asarray(sm.largest, dtype=np.float64)

    def _crossing(self, col: dict[str, FloatArray]) -> None:
        """The quantities of the crossing and the lateral motion into the cache
        (sampler.region.kinematics)."""
        c = self._cache
        kin = crossing_kinematics(self.p, self.lane_width / 2.0)
        c["t_cross"] = kin.t_cross + DEFAULT_LEAD_IN  # scenario time, as t_p
        c["v_cross"] = kin.v_cross
        c["v_ego"] = kin.v_cross + col["dv"]
        c["thw"] = np.where(c["v_ego"] > 0, col["gap"] / np.where(
            c["v_ego"] > 0, c["v_ego"], 1.0), np.inf)
        c["thw"][np.isnan(c["v_ego"])] = np.nan
        c["lat_disp"] = np.abs(kin.y_end)
        c["cross_margin"] = c["lat_disp"] - self.lane_width / 2.0
        start = np.where(col["p_y1"] > 0, -self.lane_width, self.lane_width)
        c["lat_offset"] = start + kin.y_end
        c["end_margin"] = self.lane_width / 2.0 - np.abs(c["lat_offset"])
        c["max_lat_speed"] = kin.max_lat_speed


def derive(params: ArrayLike | Mapping[str, ArrayLike], names: Iterable[str] | None = None,
           *, lane_width: float = DEFAULT_LANE_WIDTH, model: Any = None
           ) -> dict[str, FloatArray]:
    """Evaluate derived quantities for many parameter vectors.

    Parameters
    ----------
    params : array-like of shape (n, 8) in ``PARAM_NAMES`` order, or a mapping/DataFrame
        with those columns. SI units.
    names : iterable of str, optional
        Which quantities (parameters or ``DERIVED`` names); default all of ``DERIVED``.
    lane_width : float
        Lane width in m.
    model : CutInGMM, optional
        Needed for the model quantities (``density_pct``); without it they are left out of
        the default names and an error when asked for.

    Returns
    -------
    dict of name -> ndarray of shape (n,)
    """
    arr = _params_matrix(params)
    q = _Quantities(arr, float(lane_width), model)
    wanted = ([k for k, v in DERIVED.items() if model is not None or not v.model]
              if names is None else list(names))
    return {name: np.array(q[name], dtype=np.float64) for name in wanted}


def implied_bounds(constraints: Iterable[Constraint]) -> tuple[Constraint, ...]:
    """The ``btn_bound`` limits that lower limits on ``btn`` or ``a_req`` imply.

    ``btn_bound >= btn`` for every vector (``sampler.region.btn_bound``), so ``btn > c`` and
    ``btn >= c`` imply ``btn_bound >= c``, and ``a_req > c`` implies
    ``btn_bound >= c / decel_max``: adding them changes no row inside a region; it spares
    the simulation of the rows they rule out. Only positive limits imply one.
    """
    decel_max = CriticalitySettings().decel_max
    out = []
    for c in constraints:
        if c.op in (">", ">=") and c.value > 0 and c.name in ("btn", "a_req"):
            value = c.value if c.name == "btn" else c.value / decel_max
            out.append(Constraint(name="btn_bound", op=">=", value=value))
    return tuple(out)


class Region(BaseModel):
    """A region of the parameter space: constraints AND (by default) the physical bounds.

    JSON: ``{"constraints": [{"name": "ttc", "op": "<", "value": 3}],
    "lane_width": 3.75, "physical_bounds": true}``.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    constraints: tuple[Constraint, ...] = ()
    lane_width: float = Field(default=DEFAULT_LANE_WIDTH, gt=0, le=10,
                              description="lane width in m")
    physical_bounds: bool = True
    _model: Any = PrivateAttr(default=None)  # for the model quantities (bind)

    def bind(self, model: Any) -> Region:
        """This region with ``model`` for its model quantities (``density_pct``); a region
        already bound keeps its model."""
        if self._model is not None:
            return self
        out = self.model_copy()
        out._model = model
        return out

    def _key(self) -> tuple[Any, ...]:
        return (self.constraints, self.lane_width, self.physical_bounds)

    def __eq__(self, other: object) -> bool:
        """Same constraints, lane width and bounds (the bound model is not compared)."""
        if not isinstance(other, Region):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def quantities(self, params: ArrayLike | Mapping[str, ArrayLike],
                   names: Iterable[str]) -> dict[str, FloatArray]:
        """``derive`` with the region's lane width and bound model."""
        return derive(params, names, lane_width=self.lane_width, model=self._model)

    @classmethod
    def from_constraints(cls, constraints: Iterable[Any] = (), *,
                         lane_width: float = DEFAULT_LANE_WIDTH,
                         physical_bounds: bool = True) -> Region:
        """Build from Constraint objects, mappings or short-form strings."""
        if isinstance(constraints, str | Mapping | Constraint):
            constraints = [constraints]
        cs = tuple(_as_constraint(c) for c in constraints)
        if not (isinstance(lane_width, int | float) and 0 < lane_width <= 10):
            raise ConstraintError(f"lane_width: must be in (0, 10] m, got {lane_width!r}",
                                  field="lane_width", problem="out of range", value=lane_width)
        return cls(constraints=cs, lane_width=float(lane_width), physical_bounds=physical_bounds)

    @property
    def all_constraints(self) -> tuple[Constraint, ...]:
        """The user's constraints followed by the physical bounds (when on)."""
        return self.constraints + (PHYSICAL_BOUNDS if self.physical_bounds else ())

    def describe(self) -> str:
        """Short human-readable form, e.g. ``ttc<3 & physical bounds``."""
        parts = [str(c) for c in self.constraints]
        if self.physical_bounds:
            parts.append("physical bounds")
        return " & ".join(parts) if parts else "everything"

    def _mask(self, arr: FloatArray, constraints: Sequence[Constraint]) -> BoolArray:
        needs = [c.name for c in constraints if c.needs_model]
        if needs and self._model is None:
            raise ConstraintError(f"{needs[0]} needs the model: use sample() or "
                                  "estimate_p_region(), or Region.bind(model)")
        mask: BoolArray = np.asarray(np.isfinite(arr).all(axis=1), dtype=bool)
        q = _Quantities(arr, self.lane_width, self._model)
        for c in constraints:
            if c.tier == 0 and not c.needs_model:
                mask &= c.mask(q[c.name])
        # the costly groups only on the rows that are still in: the model quantities (a
        # density and a nearest-neighbour query per row), the btn bound (stated or
        # implied; cheap where it is far below its limit), the kinematics, the criticality
        bound = [c for c in (*constraints, *implied_bounds(constraints))
                 if c.name == "btn_bound"]
        groups = ([c for c in constraints if c.needs_model], bound,
                  [c for c in constraints if c.tier == 1 and c.name != "btn_bound"],
                  [c for c in constraints if c.tier == 2])
        for costly in groups:
            idx = np.flatnonzero(mask)
            if not costly or not idx.size:
                continue
            stop_at = max((c.value for c in costly if c.name == "btn_bound"
                           and c.op in (">", ">=")), default=0.0)
            q2 = _Quantities(arr[idx], self.lane_width, self._model, max(stop_at, 0.0))
            sub = np.ones(idx.size, dtype=bool)
            for c in costly:
                sub &= c.mask(q2[c.name])
            mask[idx] = sub
        return mask

    def contains(self, params: ArrayLike | Mapping[str, ArrayLike]) -> BoolArray:
        """Rows inside the region (constraints and bounds), shape (n,) bool.

        Cheap constraints are tested first on all rows; the kinematic ones (crossing
        time, ...) only on the rows that survive. Rows with a NaN are outside.
        """
        return self._mask(_params_matrix(params), self.all_constraints)

    def in_bounds(self, params: ArrayLike | Mapping[str, ArrayLike]) -> BoolArray:
        """Rows inside the physical bounds only (all True when the bounds are off)."""
        arr = _params_matrix(params)
        if not self.physical_bounds:
            return np.asarray(np.isfinite(arr).all(axis=1), dtype=bool)
        return self._mask(arr, PHYSICAL_BOUNDS)

    def violations(self, params: ArrayLike | Mapping[str, ArrayLike]) -> dict[str, BoolArray]:
        """For every constraint and bound (by its short form), the rows that violate it."""
        arr = _params_matrix(params)
        q = _Quantities(arr, self.lane_width, self._model)
        return {str(c): ~c.mask(q[c.name]) for c in self.all_constraints}
