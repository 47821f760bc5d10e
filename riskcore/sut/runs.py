"""What each run reports (:class:`RunBatch`, :data:`RUN_FIELDS`) and the comparison with
the careful driver (:func:`compare_careful`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from riskcore.sut.errors import SutError

__all__ = ["RUN_FIELDS", "RunBatch", "RunField", "compare_careful"]


class RunField(NamedTuple):
    """One per-run field: unit ("" for bool/str), kind, meaning."""

    unit: str
    kind: str  # "bool" | "float" | "str"
    doc: str


#: the per-run fields, in order: name -> (unit, kind, meaning)
RUN_FIELDS: dict[str, RunField] = {
    "collided": RunField("", "bool", "the ego's box overlapped the cutter's"),
    "impact_speed": RunField("m/s", "float", "relative speed at contact, the norm of the "
                             "velocity difference (as the criticality record); 0 without"),
    "t_contact": RunField("s", "float", "contact time, scenario time (NaN: none)"),
    "min_ttc": RunField("s", "float", "smallest TTC (clearance ahead in the ego's lane / "
                        "closing speed) from t_p on (inf: never closing)"),
    "min_thw": RunField("s", "float", "smallest time headway (clearance / ego speed) from "
                        "t_p on (inf: never ahead in the lane)"),
    "min_gap": RunField("m", "float", "smallest clearance ahead of the ego inside its "
                        "lane band from t_p on (0 with contact; inf: never ahead in it), "
                        "as the record's <driver>_min_gap"),
    "max_decel": RunField("m/s²", "float", "largest deceleration of the ego (>= 0)"),
    "max_jerk": RunField("m/s³", "float", "largest mean |jerk| over a step (the snap to 0 "
                         "at standstill not counted)"),
    "t_brake_rel_tp": RunField("s", "float", "first command <= -brake_threshold, relative "
                               "to t_p (NaN: never, or no t_p)"),
    "r_dep_peak": RunField("-", "float", "largest Wagner r_dep of the SUT's own drive at "
                           "the batch's steps until the end (NaN: not asked for, "
                           "simulate(risk=True))"),
    "r_ind_peak": RunField("-", "float", "largest r_ind likewise (NaN: not asked for)"),
    "r_dep_time_above": RunField("s", "float", "time with r_dep >= 0.5 (steps x the "
                                 "batch's step; NaN: not asked for)"),
    "must_avoid": RunField("", "bool", "UN R157 5.2.5.2 / EU 2022/1426: the TTC when the "
                           "cutter is 0.3 m into the lane exceeds the regulation's "
                           "threshold (6 m/s² variant unless set)"),
    "violation": RunField("", "bool", "must_avoid and collided"),
    "ttc_intrusion": RunField("s", "float", "the TTC at that moment (NaN: never 0.3 m in; "
                              "inf: not closing)"),
    "v_rel_intrusion": RunField("m/s", "float", "the closing speed at that moment"),
    "end_time": RunField("s", "float", "the run ended (contact, resolution or t_max)"),
    "end": RunField("", "str", "contact | settled | left_behind | no_conflict | t_max"),
}


@dataclass
class RunBatch:
    """The outcomes of N runs: one (N,) array per name of :data:`RUN_FIELDS`.

    ``profiles`` (only when asked for): ``t`` (K,) and (N, K) arrays ``x``, ``v``, ``a``
    of the ego (NaN after a run's end), and ``r_dep`` (N, T) at the batch's steps when
    the risk was computed. ``sut`` names the system.
    """

    collided: NDArray[np.bool_]
    impact_speed: NDArray[np.float64]
    t_contact: NDArray[np.float64]
    min_ttc: NDArray[np.float64]
    min_thw: NDArray[np.float64]
    min_gap: NDArray[np.float64]
    max_decel: NDArray[np.float64]
    max_jerk: NDArray[np.float64]
    t_brake_rel_tp: NDArray[np.float64]
    r_dep_peak: NDArray[np.float64]
    r_ind_peak: NDArray[np.float64]
    r_dep_time_above: NDArray[np.float64]
    must_avoid: NDArray[np.bool_]
    violation: NDArray[np.bool_]
    ttc_intrusion: NDArray[np.float64]
    v_rel_intrusion: NDArray[np.float64]
    end_time: NDArray[np.float64]
    end: NDArray[np.str_]
    sut: str = ""
    profiles: dict[str, NDArray[Any]] | None = field(default=None, repr=False)

    FIELDS = RUN_FIELDS

    def __len__(self) -> int:
        return int(self.collided.shape[0])

    def records(self) -> list[dict[str, Any]]:
        """One JSON-safe dict per run (inf and NaN as None), in the order of RUN_FIELDS."""
        cols = {name: getattr(self, name) for name in RUN_FIELDS}
        out = []
        for i in range(len(self)):
            rec: dict[str, Any] = {}
            for name, spec in RUN_FIELDS.items():
                value = cols[name][i]
                if spec.kind == "bool":
                    rec[name] = bool(value)
                elif spec.kind == "str":
                    rec[name] = str(value)
                else:
                    f = float(value)
                    rec[name] = f if math.isfinite(f) else None
            out.append(rec)
        return out

    def subset(self, index: NDArray[np.intp] | slice) -> RunBatch:
        """The runs ``index`` (profiles left out)."""
        kw: dict[str, Any] = {name: getattr(self, name)[index] for name in RUN_FIELDS}
        return RunBatch(**kw, sut=self.sut)

    @staticmethod
    def concat(parts: list[RunBatch]) -> RunBatch:
        """The runs of several batches in order (profiles left out)."""
        if not parts:
            raise SutError("parts: expected at least one RunBatch")
        kw: dict[str, Any] = {name: np.concatenate([getattr(p, name) for p in parts])
                              for name in RUN_FIELDS}
        return RunBatch(**kw, sut=parts[0].sut)

    def replace(self, **changes: Any) -> RunBatch:
        return dataclasses.replace(self, **changes)


def compare_careful(sut_runs: RunBatch, careful_runs: RunBatch, *,
                    tol: float = 0.01) -> NDArray[np.str_]:
    """Per run: ``'worse'`` when the SUT collides where the careful driver does not, or
    both collide and the SUT's impact speed is higher by more than ``tol`` m/s;
    ``'better'`` the other way round; else ``'same'``."""
    if len(sut_runs) != len(careful_runs):
        raise SutError(f"careful_runs: expected {len(sut_runs)} runs, got {len(careful_runs)}")
    a_c, b_c = sut_runs.collided, careful_runs.collided
    a_v, b_v = sut_runs.impact_speed, careful_runs.impact_speed
    worse = (a_c & ~b_c) | (a_c & b_c & (a_v > b_v + tol))
    better = (~a_c & b_c) | (a_c & b_c & (a_v < b_v - tol))
    out = np.full(a_c.shape[0], "same", dtype="<U6")
    out[worse] = "worse"
    out[better] = "better"
    return out
