"""The criticality record's settings and fields (:mod:`riskcore.criticality` computes it)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from riskcore.errors import RiskcoreError, SettingsError

__all__ = ["CLASSES", "CRITICALITY_FIELDS", "Criticality", "CriticalityError",
           "CriticalitySettings", "FieldSpec", "G", "settings_from_dict"]

#: standard gravity in m/s² (R157 gives the careful driver's deceleration in g)
G = 9.81

#: the classes, from harmless to hopeless
CLASSES: tuple[str, ...] = ("no_conflict", "preventable", "unpreventable", "unavoidable")


class CriticalityError(RiskcoreError):
    """A scenario cannot be given a criticality record (the message says why)."""


#: settings for which +inf is a meaning, not an error
_MAY_BE_INF = frozenset({"critical_ttc"})


@dataclass(frozen=True)
class CriticalitySettings:
    """Parameters of the criticality record. Frozen; validated on construction.

    UN R157 Annex 4 Appendix 3 careful and competent (C&C) driver (figures also in
    Mattas et al. 2022, Accident Analysis & Prevention 174, 106743):

    wandering_zone : float
        Lateral wandering distance in m (0.375); moving beyond it makes a cut-in
        perceivable.
    reaction_time : float
        From perception to the start of braking, s (0.75).
    jerk : float
        Brake build-up, m/s³ (12.65: 0.774 g in 0.6 s).
    decel_max : float
        Full deceleration, m/s² (0.774 g = 7.593).
    critical_ttc : float
        The C&C driver reacts only to a developing conflict: the cutter ahead and the
        gap closing with TTC below this, s. Default +inf: any closing gap (UN R157's
        cut-in case is a cutter slower than the ALKS vehicle, para. 5.2.5.2 (a));
        2.0 is the gate of the JRC-FSM implementation (docs/criticality.md). The only
        setting that may be +inf.

    RSS (Shalev-Shwartz, Shammah, Shashua 2017, "On a formal model of safe and scalable
    self-driving cars"; parameter values as in the comparison of Mattas et al. 2022):

    rss_response_time : float
        rho, s (0.75).
    rss_accel_max : float
        Worst-case acceleration of the ego during rho, m/s² (3.0).
    rss_brake_min : float
        Braking the ego guarantees, m/s² (6.0; used in the safe distance only: the
        simulated response brakes like the C&C driver, jerk ``jerk`` up to ``decel_max``).
    rss_brake_max : float
        Hardest braking of the vehicle ahead, m/s² (6.0).
    rss_lat_margin : float
        mu, lateral fluctuation margin, m (0.3).
    rss_lat_accel_max : float
        Lateral acceleration of the cutter during rho and its lateral braking, m/s² (1.0).

    Numerics:

    step : float
        Time step of the closed-loop simulations, s (0.01); contact times are refined by
        a bracketing root search between steps.
    tail : float
        The simulations continue past the scenario's end (both vehicles at constant
        velocity) for this long, s (10), plus the time to close the gap if it is closing,
        at most ``follow_horizon``.
    follow_horizon : float
        A gap that would close more than this long after the scenario's end is taken as
        no conflict, s (60): e.g. 6 m closing at 4 mm/s.
    ttr_tail : float
        The TTR scan's horizon runs this long past the constant-speed collision, s (1.0).
    alarm_level : float
        r_dep level of ``alarm_time`` (0.5).
    """

    wandering_zone: float = 0.375
    reaction_time: float = 0.75
    jerk: float = 12.65
    decel_max: float = 0.774 * G
    critical_ttc: float = math.inf
    rss_response_time: float = 0.75
    rss_accel_max: float = 3.0
    rss_brake_min: float = 6.0
    rss_brake_max: float = 6.0
    rss_lat_margin: float = 0.3
    rss_lat_accel_max: float = 1.0
    step: float = 0.01
    tail: float = 10.0
    follow_horizon: float = 60.0
    ttr_tail: float = 1.0
    alarm_level: float = 0.5

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise SettingsError(f"{f.name}: expected a number, got {value!r}")
            if f.name in _MAY_BE_INF and value == math.inf:
                object.__setattr__(self, f.name, math.inf)
                continue
            if not math.isfinite(value) or value < 0:
                what = ("a number >= 0 or inf" if f.name in _MAY_BE_INF
                        else "a finite number >= 0")
                raise SettingsError(f"{f.name}: must be {what}, got {value!r}")
            object.__setattr__(self, f.name, float(value))
        for name in ("jerk", "decel_max", "rss_brake_min", "rss_brake_max",
                     "rss_lat_accel_max", "step", "wandering_zone"):
            if getattr(self, name) <= 0:
                raise SettingsError(f"{name}: must be > 0, got {getattr(self, name)}")
        if self.step > 0.1:
            raise SettingsError(f"step: at most 0.1 s, got {self.step}")

    def replace(self, **changes: Any) -> CriticalitySettings:
        """A copy with some fields changed (validated). Unknown names are an error."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise SettingsError(f"unknown setting(s) {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


class FieldSpec(NamedTuple):
    """One field of the record: unit ("-" dimensionless, "" text/bool), kind, meaning."""

    unit: str
    kind: str  # "float" | "bool" | "str"
    doc: str


def _driver_fields(name: str, label: str) -> dict[str, FieldSpec]:
    return {
        f"{name}_collision": FieldSpec("", "bool", f"{label}: does it hit the cutter?"),
        f"{name}_impact_speed": FieldSpec(
            "m/s", "float", f"{label}: relative speed at contact (0 without contact)"),
        f"{name}_min_gap": FieldSpec(
            "m", "float", f"{label}: smallest clearance to the cutter in its lane after "
            "t_p (0 with contact; inf: never ahead in its lane)"),
    }


#: The flat record: name -> (unit, kind, meaning). The same names everywhere.
CRITICALITY_FIELDS: dict[str, FieldSpec] = {
    "t_p": FieldSpec("s", "float", "perception moment, scenario time (from the scenario's "
                     "first sample): the cutter has moved 0.375 m towards the ego lane "
                     "(UN R157); null: never"),
    "t_cross": FieldSpec("s", "float", "the cutter's centre crosses the lane marking, "
                         "scenario time (as t_p)"),
    "ttr_true": FieldSpec("s", "float", "time to react at t_p against the cutter's actual "
                          "path, s after t_p (inf: no collision at constant speed; "
                          "0: nothing avoids it)"),
    "ttr_manoeuvre": FieldSpec("", "str", "manoeuvre(s) giving ttr_true; 'none' when "
                               "nothing works; null without collision"),
    "a_req": FieldSpec("m/s²", "float", "constant deceleration needed when braking starts "
                       "0.75 s after t_p (0: none needed; inf: contact before)"),
    "btn": FieldSpec("-", "float", "brake threat number a_req / (0.774 g), the ranking "
                     "(highest first); >= 1: even an instant full brake 0.75 s after t_p is "
                     "too late. The class, not btn, says whether the careful driver (whose "
                     "brake builds up over 0.6 s) prevents it: some cut-ins with btn below 1 "
                     "are unpreventable"),
    "class": FieldSpec("", "str", "no_conflict | preventable | unpreventable | "
                       "unavoidable"),
    **_driver_fields("none", "ego at its scripted (constant) speed"),
    **_driver_fields("r157_cc", "UN R157 careful and competent driver"),
    "r157_cc_t_brake": FieldSpec("s", "float", "R157 driver: braking starts, scenario time "
                                 "(null: never)"),
    **_driver_fields("rss", "RSS longitudinal response"),
    "rss_t_brake": FieldSpec("s", "float", "RSS driver: braking starts, scenario time "
                             "(null: never)"),
    "r_dep_tp": FieldSpec("-", "float", "Wagner's risk r_dep at t_p, scripted ego"),
    "r_ind_tp": FieldSpec("-", "float", "Wagner's r_ind at t_p, scripted ego"),
    "r_dep_cross": FieldSpec("-", "float", "r_dep at the crossing, scripted ego (null: not "
                             "asked for, wagner_scan)"),
    "r_ind_cross": FieldSpec("-", "float", "r_ind at the crossing, scripted ego"),
    "r_dep_tp_r157": FieldSpec("-", "float", "r_dep at t_p, ego = R157 driver"),
    "r_ind_tp_r157": FieldSpec("-", "float", "r_ind at t_p, ego = R157 driver"),
    "r_dep_cross_r157": FieldSpec("-", "float", "r_dep at the crossing, ego = R157 driver"),
    "r_ind_cross_r157": FieldSpec("-", "float", "r_ind at the crossing, ego = R157 driver"),
    "alarm_time": FieldSpec("s", "float", "from t_p until the scripted-ego r_dep first "
                            "reaches 0.5 (null: never, or not asked for: wagner_scan)"),
    "risk_peak": FieldSpec("-", "float", "maximum r_dep over the run, scripted ego that never "
                           "reacts, so 1 on nearly every collision course: not a ranking "
                           "(null: not asked for, wagner_scan)"),
}


@dataclass(frozen=True)
class Criticality:
    """The criticality record of one scenario; ``to_record()`` is the flat form.

    ``values`` maps every name of :data:`CRITICALITY_FIELDS` to a float (may be +inf), a
    bool, a str or None.
    """

    values: dict[str, float | bool | str | None]

    def __post_init__(self) -> None:
        missing = [k for k in CRITICALITY_FIELDS if k not in self.values]
        extra = [k for k in self.values if k not in CRITICALITY_FIELDS]
        if missing or extra:
            raise CriticalityError(f"record fields: missing {missing}, unknown {extra}")

    def __getitem__(self, name: str) -> float | bool | str | None:
        return self.values[name]

    @property
    def category(self) -> str:
        """The class (``"class"`` is a Python keyword)."""
        return str(self.values["class"])

    def to_record(self) -> dict[str, float | bool | str | None]:
        """Flat dict in the order of CRITICALITY_FIELDS (a fresh copy)."""
        return {k: self.values[k] for k in CRITICALITY_FIELDS}


def settings_from_dict(data: Mapping[str, Any]) -> CriticalitySettings:
    """Build settings from a mapping of field names (missing ones take the defaults)."""
    if not isinstance(data, Mapping):
        raise SettingsError("settings: expected an object")
    return CriticalitySettings().replace(**dict(data))
