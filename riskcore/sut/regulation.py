"""The regulation's own verdict on a cut-in: must the system avoid it?

UN R157 para. 5.2.5.2 and Commission Implementing Regulation (EU) 2022/1426, Annex III,
Part 1, 1.4.2 (the same relation; tabled by the German KBA, "Test scenarios", from AFGBV
Anlage 1 Teil 2 10.2.5): a collision with a vehicle cutting in must be avoided when the
TTC at the moment the cutting-in vehicle has entered the system's lane by more than 0.3 m
past the lane marking is above

    TTC_min(v_rel) = v_rel / (2 a) + t_r + a / (2 j)

v_rel the relative speed (m/s, > 0 when the ego is faster), ``a`` the deceleration the
system is expected to reach, ``t_r`` a reaction time and ``a / j`` the time of a linear
braking ramp at jerk ``j`` (the ramp counted, to first order, as half its duration of lost
braking; the speed lost during the ramp is neglected, as in the tables). The tables'
figures (6 m/s²: 0.48 s at 10 km/h, 0.71 at 20, 0.94 at 30, 1.18 at 40, 1.41 at 50, 1.64 at
60; 2.4 m/s², with standing occupants: 0.74, 1.32, 1.90, 2.47, 3.05, 3.63) are reproduced
to their two decimals by one pair, t_r = 0.1 s and j = 20 m/s³: the constant t_r + a/(2j)
is 0.25 s at 6 m/s² and 0.16 s at 2.4 m/s² (two tables, two unknowns; the 2.4 m/s² table
allows 0.159-0.160 s only, the 6 m/s² one 0.245-0.254 s).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riskcore.sut.errors import SutError

__all__ = ["INTRUSION_DEPTH", "MUST_AVOID_VARIANTS", "must_avoid", "must_avoid_ttc"]

#: how far past the lane marking the cutter must be for the regulation's moment, m
INTRUSION_DEPTH = 0.3
#: reaction time and braking-ramp jerk that reproduce the regulation's tables
REACTION_TIME = 0.1
RAMP_JERK = 20.0
#: variant name -> the deceleration a in m/s²
MUST_AVOID_VARIANTS: dict[str, float] = {"6": 6.0, "2.4": 2.4}


def _decel(variant: str) -> float:
    try:
        return MUST_AVOID_VARIANTS[str(variant)]
    except KeyError:
        raise SutError(f"variant: expected one of {sorted(MUST_AVOID_VARIANTS)}, got "
                       f"{variant!r}") from None


def must_avoid_ttc(v_rel: ArrayLike, variant: Literal["6", "2.4"] | str = "6"
                   ) -> NDArray[np.float64]:
    """The regulation's TTC threshold in s for the relative speed ``v_rel`` (m/s)."""
    a = _decel(variant)
    v = np.asarray(v_rel, dtype=np.float64)
    return np.asarray(v / (2.0 * a) + REACTION_TIME + a / (2.0 * RAMP_JERK), dtype=np.float64)


def must_avoid(ttc: ArrayLike, v_rel: ArrayLike,
               variant: Literal["6", "2.4"] | str = "6") -> NDArray[np.bool_]:
    """Vectorised verdict: True where the system must avoid the cut-in.

    ``ttc`` (s) and ``v_rel`` (m/s) at the moment the cutter is 0.3 m into the ego lane
    (NaN: it never gets there, so the cut-in is not one the regulation speaks of: False).
    ``ttc = +inf`` (not closing) must be avoided. True where ``ttc > must_avoid_ttc``.
    """
    t = np.asarray(ttc, dtype=np.float64)
    v = np.asarray(v_rel, dtype=np.float64)
    thr = must_avoid_ttc(np.maximum(v, 0.0), variant)
    with np.errstate(invalid="ignore"):
        return np.asarray(~np.isnan(t) & (t > thr), dtype=np.bool_)
