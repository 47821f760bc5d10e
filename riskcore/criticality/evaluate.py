"""Criticality of a cut-in: margins at the perception moment, reacting reference drivers.

One :class:`Criticality` record per concrete scenario (docs/criticality.md explains the
semantics for test engineers; CONTRACT: the flat field names of ``CRITICALITY_FIELDS``).

The cutter is the object with id ``"cutter"`` (else the first object); it follows its own
recorded or generated motion and does not react. The ego reacts longitudinally only,
along its own path (the kernels in :mod:`riskcore.criticality.kernels` work in the ego's
frame; for a generated cut-in that is the road frame).

Perception moment ``t_p`` (UN R157 Annex 4 Appendix 3, cut-in: the lateral movement of
the cutting-in vehicle beyond the lateral wandering distance of 0.375 m): the first time
the cutter's *centre* has moved ``wandering_zone`` towards the ego, in the road's lateral
coordinate y, from its lateral position at the first sample of the scenario (a generated
cut-in starts at the centre of the adjacent lane, where it drives until its lateral
motion starts); linear interpolation between samples. The side "towards the ego" is the
sign of ``y_ego - y_cutter`` at the first sample. For a body that has not yawed yet every
point of its near edge moves as its centre does.

Reference drivers (all from the same scripted motion until they brake):

* ``none``: the scripted ego (constant speed for a generated cut-in);
* ``r157_cc``: perceives the cut-in at ``t_p``; it starts its reaction at the first
  moment >= ``t_p`` at which a conflict is developing: the cutter is ahead and the
  centre-line longitudinal gap is closing (or already closed). ``critical_ttc`` (default
  +inf: any closing gap) can narrow this to TTC < ``critical_ttc`` (2 s: the JRC-FSM
  implementation's gate). It brakes ``reaction_time`` later with jerk ``jerk`` up to
  ``decel_max`` and keeps braking to standstill;
* ``rss``: Shalev-Shwartz et al. (2017) longitudinal response: when the longitudinal and
  the lateral RSS distances are both violated, it brakes after the response time ``rho``
  with the same jerk-limited braking.

``a_req`` is the constant deceleration that avoids contact when braking starts at
``t_p + reaction_time`` (0 without collision at constant speed, +inf when contact comes
before), ``btn = a_req / decel_max``. ``ttr_true`` is riskcore's TTR scan (max of TTS, TTB,
TTK) at ``t_p`` with the cutter's actual future as the only predicted trajectory.
Wagner's r_dep/r_ind come from riskcore's scene engine.
"""

from __future__ import annotations

import math

import numpy as np

from riskcore.criticality import kernels as _ck
from riskcore.criticality.drivers import (
    _braked,
    _check_not_cut_off,
    _cutter_index,
    _frames,
    _lane_width,
    _run_drivers,
    _ttr_true,
    crossing_time,
    perception_time,
)
from riskcore.criticality.record import (
    Criticality,
    CriticalityError,
    CriticalitySettings,
)
from riskcore.criticality.wagner import _wagner_fields
from riskcore.scenario import ConcreteScenario
from riskcore.settings import RiskSettings
from riskcore.surfaces import InputSurfaces

__all__ = ["evaluate_criticality"]

def evaluate_criticality(scenario: ConcreteScenario, *, lane_width: float | None = None,
                         settings: CriticalitySettings | None = None,
                         risk_settings: RiskSettings | None = None,
                         surfaces: InputSurfaces | None = None,
                         wagner_scan: bool = True) -> Criticality:
    """The criticality record of one cut-in (see the module docstring and CONTRACT).

    Parameters
    ----------
    scenario : ConcreteScenario
        The ego and at least one object; the cutter is the object ``"cutter"`` (else the
        first). Wagner's risks use every object.
    lane_width : float, optional
        Lane width in m for the crossing moment (default: the scenario's provenance
        ``lane_width``, else 3.75).
    settings : CriticalitySettings, optional
    risk_settings : RiskSettings, optional
        Wagner's risk and the TTR scan's manoeuvres (riskcore's defaults when None).
    surfaces : InputSurfaces, optional
        Input distributions of Wagner's risk (the packaged default when None).
    wagner_scan : bool
        Compute ``alarm_time`` and ``risk_peak``, which need the scripted ego's r_dep at
        the scenario's steps (most of the record's cost), and Wagner's risks at the
        crossing; False: they are None (the risks at t_p are always computed).

    Returns
    -------
    Criticality
    """
    if not isinstance(scenario, ConcreteScenario):
        raise CriticalityError(f"scenario: expected a ConcreteScenario, got "
                               f"{type(scenario).__name__}")
    s = settings or CriticalitySettings()
    rs = risk_settings or RiskSettings()
    lw = _lane_width(scenario, lane_width)
    _check_not_cut_off(scenario)
    for name, track in (("ego", scenario.ego),
                        *((f"objects[{i}]", o) for i, o in enumerate(scenario.objects))):
        if (track.v < 0).any():
            k = int(np.flatnonzero(track.v < 0)[0])
            raise CriticalityError(f"{name}.v[{k}]: speed must be >= 0, got {track.v[k]}")
    cutter = scenario.objects[_cutter_index(scenario)]
    f = _frames(scenario.t, scenario.ego, cutter, s)
    t_p = perception_time(scenario, cutter, s.wandering_zone)
    prov_cross = scenario.provenance.get("t_cross")
    if isinstance(prov_cross, int | float) and not isinstance(prov_cross, bool) and \
            scenario.params:
        t_cross: float | None = float(prov_cross)
    else:
        t_cross = crossing_time(scenario, cutter, lw)
    d = _run_drivers(f, t_p, s)
    c_none = d.none[0]
    none_coll = not math.isnan(c_none)
    r157_coll = not math.isnan(d.r157[0])
    rec: dict[str, float | bool | str | None] = {"t_p": t_p, "t_cross": t_cross}
    # margins at t_p
    if t_p is None:
        a_req: float | None = 0.0 if not none_coll else None
        ttr: float | None = math.inf if not none_coll else None
        man: str | None = None
    elif not none_coll:
        a_req, ttr, man = 0.0, math.inf, None
    else:
        t_b0 = t_p + s.reaction_time
        a_req = math.inf if c_none <= t_b0 else float(_ck.required_decel(
            f.t0, f.h, f.cs, f.cd, f.cpsi, f.cv, f.es, f.ev, f.ehl, f.ehw, f.chl, f.chw, t_b0,
            f.k_const))
        ttr, man = _ttr_true(f, t_p, c_none, rs, s)
    rec["ttr_true"] = ttr
    rec["ttr_manoeuvre"] = man
    rec["a_req"] = a_req
    rec["btn"] = None if a_req is None else a_req / s.decel_max
    if not none_coll:
        cls = "no_conflict"
    elif not r157_coll:
        cls = "preventable"
    elif man == "none":
        cls = "unavoidable"
    else:
        cls = "unpreventable"
    rec["class"] = cls
    for name, (contact, speed, gap) in (("none", d.none), ("r157_cc", d.r157),
                                        ("rss", d.rss)):
        rec[f"{name}_collision"] = not math.isnan(contact)
        rec[f"{name}_impact_speed"] = float(speed)
        rec[f"{name}_min_gap"] = float(gap)
    rec["r157_cc_t_brake"] = _braked(d.r157_t_brake, d.r157[0])
    rec["rss_t_brake"] = _braked(d.rss_t_brake, d.rss[0])
    rec.update(_wagner_fields(scenario, f, t_p, t_cross, d, rs, surfaces, s,
                              scan=wagner_scan))
    return Criticality(values=rec)
