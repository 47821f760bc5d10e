"""Exposure of a data set and rates of a region: cut-ins per hour and per 10^6 km.

A fitted model describes the cut-ins of its training table; the table was recorded in some
amount of driving, its *exposure*. With ``n`` cut-ins in ``H`` hours (``K`` km) the rate
of cut-ins is ``lambda_h = n / H`` per hour (``n / K`` per km), and a region A of the
parameter space has the rate ``lambda_h P(A)``: "cut-ins with ttc < 3 s per hour".

Sources of exposure:

* TNO cut-ins (the embedded data; de Gelder et al., "Risk Quantification for Automated
  Driving Systems in Driving Scenarios", IEEE Access 9:168953-168970, 2021): the source's
  uncertainty analysis treats its cut-ins as coming from 63 hours of driving (``N_HOUR``
  in its ``uncertainty.py``; ``../shared/data/tno-cutin/README.md``). The source gives no
  distance, so TNO rates are per hour only. ``n`` counts the events the model was fitted
  to (208 of 297: the conversion left 89 out as implausible, see the data's PROVENANCE.md):
  the rate is that of cut-ins of the kind the model describes, a lower bound of the rate
  of all cut-ins (297 / 63 h).
* highD recordings: ``totalDrivenTime`` (s) and ``totalDrivenDistance`` (m) of every
  recording's ``recordingMeta``, summed: vehicle-hours and vehicle-km driven past the
  drone, in which every cut-in in front of any vehicle was recorded.

Intervals of a rate (``region_rates``):

* "Monte Carlo": the P(A) interval times ``lambda`` (the estimator's own uncertainty);
* "model": the bootstrap replicates (``sampler.bootstrap``) of P(A) times a Poisson
  replicate of the count, ``lambda_b = N_b / H`` with ``N_b ~ Poisson(n)`` drawn from a
  seeded Generator: the uncertainty of the data model and of the exposure count together.
The count's own exact (Garwood) Poisson interval is reported with ``lambda``.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

from sampler._exceptions import ModelError

__all__ = ["TNO_HOURS", "Exposure", "cutin_rate", "highd_exposure", "region_rates",
           "region_report", "report_text", "tno_exposure"]

#: hours of driving of the TNO cut-in data (de Gelder et al. 2021, N_HOUR in uncertainty.py)
TNO_HOURS = 63.0
TNO_SOURCE = ("de Gelder et al., IEEE Access 9:168953-168970, 2021: 63 hours of driving "
              "(N_HOUR of the source's uncertainty analysis); no distance given")


@dataclass(frozen=True)
class Exposure:
    """Driving in which a data set's cut-ins were recorded.

    Attributes
    ----------
    n_events : int
        Cut-ins counted in that driving (the model's training rows).
    hours : float or None
        Hours driven (vehicle-hours for highD); None when unknown.
    km : float or None
        Kilometres driven (vehicle-km for highD); None when unknown.
    source : str
        Where the figures come from.
    """

    n_events: int
    hours: float | None
    km: float | None
    source: str

    def __post_init__(self) -> None:
        if self.n_events < 0:
            raise ModelError(f"exposure.n_events: must be >= 0, got {self.n_events}")
        for name in ("hours", "km"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ModelError(f"exposure.{name}: must be a positive number or null, "
                                 f"got {v!r}")
        if self.hours is None and self.km is None:
            raise ModelError("exposure: give hours, km or both")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Exposure:
        try:
            return cls(n_events=int(d["n_events"]),
                       hours=None if d.get("hours") is None else float(d["hours"]),
                       km=None if d.get("km") is None else float(d["km"]),
                       source=str(d.get("source", "")))
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"exposure: expected n_events, hours/km, source ({exc})") from None


def tno_exposure(n_events: int) -> Exposure:
    """Exposure of the TNO cut-in data (see the module docstring)."""
    return Exposure(n_events=int(n_events), hours=TNO_HOURS, km=None, source=TNO_SOURCE)


def highd_exposure(recording_metas: Iterable[Any], n_events: int) -> Exposure:
    """Exposure of highD recordings from their ``recordingMeta`` tables (DataFrames with
    ``totalDrivenTime`` in s and ``totalDrivenDistance`` in m)."""
    from datasets import highd_columns as hc

    seconds = metres = 0.0
    names = 0
    for meta in recording_metas:
        seconds += float(np.sum(meta[hc.TOTAL_DRIVEN_TIME].to_numpy(dtype=np.float64)))
        metres += float(np.sum(meta[hc.TOTAL_DRIVEN_DISTANCE].to_numpy(dtype=np.float64)))
        names += 1
    if names == 0:
        raise ModelError("exposure: no highD recording given")
    return Exposure(n_events=int(n_events), hours=seconds / 3600.0 if seconds > 0 else None,
                    km=metres / 1000.0 if metres > 0 else None,
                    source=f"highD recordingMeta of {names} recording(s): totalDrivenTime, "
                           "totalDrivenDistance (vehicle-hours, vehicle-km)")


def _poisson_ci(n: int, confidence: float) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson mean from one count n."""
    a = 1.0 - confidence
    lo = 0.0 if n == 0 else float(stats.chi2.ppf(a / 2, 2 * n) / 2)
    hi = float(stats.chi2.ppf(1 - a / 2, 2 * n + 2) / 2)
    return lo, hi


def _units(exposure: Exposure) -> list[tuple[str, float]]:
    out = []
    if exposure.hours is not None:
        out.append(("per_hour", exposure.hours))
    if exposure.km is not None:
        out.append(("per_1e6_km", exposure.km / 1e6))
    return out


def cutin_rate(exposure: Exposure, confidence: float = 0.95) -> dict[str, Any]:
    """Rate of all cut-ins of the data: ``{unit: {"estimate", "ci"}}``, units ``per_hour``
    and ``per_1e6_km`` (only those the exposure has)."""
    lo, hi = _poisson_ci(exposure.n_events, confidence)
    return {unit: {"estimate": exposure.n_events / amount, "ci": [lo / amount, hi / amount]}
            for unit, amount in _units(exposure)}


def region_rates(exposure: Exposure, p_region: Mapping[str, Any] | Any,
                 model: Mapping[str, Any] | None = None, seed: int = 0,
                 confidence: float = 0.95) -> dict[str, Any]:
    """Rates of the region's cut-ins with both intervals.

    Parameters
    ----------
    p_region : PRegion or its dict (``estimate``, ``ci_low``, ``ci_high``)
    model : the "model" interval of ``sampler.bootstrap.model_interval`` (with
        ``replicates``), or None (then no model interval)

    Returns
    -------
    ``{unit: {"estimate", "mc_ci", "model_ci"}, "exposure": ..., "cutin_rate": ...}``
    """
    p = p_region if isinstance(p_region, Mapping) else p_region.to_dict()
    est, lo, hi = float(p["estimate"]), float(p["ci_low"]), float(p["ci_high"])
    out: dict[str, Any] = {"exposure": exposure.to_dict(),
                           "cutin_rate": cutin_rate(exposure, confidence),
                           "confidence": confidence}
    reps = None
    if model is not None and model.get("replicates"):
        r = np.asarray(model["replicates"], dtype=np.float64)
        counts = np.random.default_rng(seed).poisson(exposure.n_events, size=r.size)
        reps = r * counts
        reps = reps[np.isfinite(reps)]
    a = 1.0 - confidence
    for unit, amount in _units(exposure):
        lam = exposure.n_events / amount
        entry: dict[str, Any] = {"estimate": lam * est, "mc_ci": [lam * lo, lam * hi],
                                 "model_ci": None}
        if reps is not None and reps.size:
            q = np.quantile(reps / amount, [a / 2, 1 - a / 2])
            entry["model_ci"] = [float(q[0]), float(q[1])]
        out[unit] = entry
    return out


def region_report(model: Any, sample_set: Any, seed: int = 0, n_plain: int = 8192,
                  confidence: float = 0.95) -> dict[str, Any]:
    """P(A) with its "Monte Carlo" interval, the "model" interval (when the model has
    bootstrap replicates) and the rates (when it has an exposure), for a sample set drawn
    from the model: what the CLI and the API show beside P(A)."""
    from sampler.bootstrap import model_interval

    p = sample_set.p_region
    out: dict[str, Any] = {"p_region": {"estimate": p.estimate, "mc_ci": [p.ci_low, p.ci_high],
                                        "model_ci": None, "cov": p.cov,
                                        "method": p.method}}
    model_iv = None
    if getattr(model, "bootstrap_", None):
        names = list(model.features_)
        z_in = model.to_z(sample_set.params[names].to_numpy(dtype=np.float64))
        rng = np.random.default_rng(seed)
        z_plain = model.sample_z(int(n_plain), rng)
        in_b = sample_set.region.in_bounds(model.params_matrix(model.from_z(z_plain)))
        model_iv = model_interval(model, z_in, p.p_joint, z_plain, in_b, confidence)
        out["p_region"]["model_ci"] = model_iv["ci"]
        out["model_interval"] = {k: v for k, v in model_iv.items() if k != "replicates"}
    exp = getattr(model, "exposure_", None)
    if exp:
        rates = region_rates(Exposure.from_dict(exp), p, model_iv, seed=seed,
                             confidence=confidence)
        n = max(1, len(sample_set))
        for unit in ("per_hour", "per_1e6_km"):
            if unit in rates:  # each sample's exposure weight in this unit: they sum to it
                rates[unit]["weight_per_sample"] = rates[unit]["estimate"] / n
        out["rates"] = rates
    return out


def report_text(report: Mapping[str, Any]) -> str:
    """One line per figure: P(A) and the rates with both intervals."""
    def iv(v: Any) -> str:
        return "n/a" if v is None else f"[{v[0]:.3g}, {v[1]:.3g}]"

    p = report["p_region"]
    lines = [f"P(A) {p['estimate']:.3g}  Monte Carlo {iv(p['mc_ci'])}  model {iv(p['model_ci'])}"]
    rates = report.get("rates")
    if rates:
        for unit, label in (("per_hour", "per hour"), ("per_1e6_km", "per 10^6 km")):
            if unit in rates:
                r = rates[unit]
                lines.append(f"rate {label} {r['estimate']:.3g}  Monte Carlo {iv(r['mc_ci'])}"
                             f"  model {iv(r['model_ci'])}")
        e = rates["exposure"]
        lines.append(f"exposure: {e['n_events']} cut-ins in "
                     + " and ".join(x for x in (
                         f"{e['hours']:.4g} h" if e["hours"] else "",
                         f"{e['km']:.4g} km" if e["km"] else "") if x)
                     + f" ({e['source']})")
    return "\n".join(lines)
