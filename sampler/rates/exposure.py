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
* highD recordings: per tracked vehicle, the time it was on the recorded section
  (``numFrames / frameRate`` of ``tracksMeta``) and the distance it drove there
  (``traveledDistance``), summed over the vehicles of every recording: vehicle-hours and
  vehicle-km. That is the exposure of the extracted cut-ins: a cut-in is counted for the
  vehicle it cuts in front of (the ego), and every tracked vehicle could be an ego for the
  time and distance it was tracked. (Road-km or recording hours would count the section
  once however many vehicles drove it, and would not compare with a per-vehicle figure
  such as the TNO data's hours driven.) highD's ``totalDrivenTime`` /
  ``totalDrivenDistance`` in ``recordingMeta`` are the same sums, rounded.

Intervals of a rate (``region_rates``):

* "Monte Carlo": the P(A) interval times ``lambda`` (the estimator's own uncertainty);
* "model": the bootstrap replicates (``sampler.model.bootstrap``) of P(A) times a Poisson
  replicate of the count, ``lambda_b = N_b / H`` with ``N_b ~ Poisson(n)`` drawn from a
  seeded Generator: the uncertainty of the data model and of the exposure count together.
The count's own exact (Garwood) Poisson interval is reported with ``lambda``.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

from sampler.errors import ModelError, SamplerError
from sampler.model.memo import MODEL_SEED, memoised
from sampler.rates.bootstrap_interval import pooled_interval

__all__ = ["INTERVAL_READINGS", "TNO_HOURS", "Exposure", "cutin_rate", "highd_exposure",
           "model_interval", "model_wider", "region_rates", "region_report", "report_text",
           "tno_exposure", "uncertainty_report"]

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


def highd_exposure(driven: Mapping[str, Any], n_events: int) -> Exposure:
    """Exposure of highD recordings: ``driven`` is the extraction's exposure
    (``datasets.extract.ExtractionResult.exposure``: ``vehicle_hours``, ``vehicle_km`` summed
    over the tracked vehicles of every recording, ``recordings``)."""
    try:
        hours, km = float(driven["vehicle_hours"]), float(driven["vehicle_km"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"exposure: expected vehicle_hours and vehicle_km ({exc})") from None
    names = list(driven.get("recordings") or [])
    return Exposure(n_events=int(n_events), hours=hours if hours > 0 else None,
                    km=km if km > 0 else None,
                    source=f"highD tracksMeta of {len(names)} recording(s) "
                           f"({', '.join(map(str, names[:10]))}): per vehicle numFrames / "
                           "frameRate and traveledDistance, summed (vehicle-hours, vehicle-km)")


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
    model : the "model" interval of ``sampler.model.bootstrap.model_interval`` (with
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
                                 "model_ci": None,
                                 "model_lower_resolved": None if model is None
                                 else bool(model.get("lower_resolved", True))}
        if reps is not None and reps.size:
            q = np.quantile(reps / amount, [a / 2, 1 - a / 2])
            entry["model_ci"] = [float(q[0]), float(q[1])]
        out[unit] = entry
    return out


def uncertainty_report(model: Any, p_region: Any, region: Any,
                       n_samples: int | None = None, n_plain: int = 8192,
                       confidence: float = 0.95, per_replicate: bool = False
                       ) -> dict[str, Any]:
    """P(A) with its "Monte Carlo" interval, the "model" interval (when the model has
    bootstrap replicates: :func:`~sampler.rates.bootstrap_interval.pooled_interval`) and the
    rates (when it has an exposure) of a region whose P(A) under the model is known: what
    the CLI, the API and a catalogue's status show beside P(A).

    Parameters
    ----------
    p_region : sampler.methods.probability.PRegion of the region under the fitted model
    region : sampler.region.constraints.Region
    n_samples : samples the region was drawn with (then each sample's exposure weight in
        each unit is given, ``weight_per_sample``: they sum to the rate)

    The model interval (and the Poisson replicates of the rates' one) depend on the model
    and the region only: they are computed with ``sampler.model.memo.MODEL_SEED``, once per model
    object and region (``sampler.model.memo``), whatever seed drew the samples.
    """
    p = p_region
    out: dict[str, Any] = {"p_region": {"estimate": p.estimate, "mc_ci": [p.ci_low, p.ci_high],
                                        "model_ci": None, "cov": p.cov,
                                        "method": p.method}}
    model_iv = None
    if getattr(model, "bootstrap_", None):
        # rare when the region needed subset simulation (plain or with importance
        # sampling) under the fitted model, or when its plain run's hit rate is too low for
        # the replicates' pilot (a criticality region's: 8,192 draws; ``btn > 0.4`` is
        # plain behind btn_bound, at ~1e-5 per draw): plain draws of the replicates'
        # average do not reach it either
        costly = any(c.tier == 2 for c in region.constraints)
        thin = costly and p.n_draws > 0 and p.n_hits / p.n_draws < RARE_RATE
        try:
            model_iv = model_interval(model, region,
                                      rare=p.method in ("subset", "subset-is", "split") or thin,
                                      n_plain=n_plain, confidence=confidence,
                                      per_replicate=per_replicate)
        except SamplerError as exc:
            # P(A) under the fitted model is known; only the replicates' estimate failed
            # (e.g. a thin band their subset levels do not reach): no model interval, and
            # why, instead of failing the whole answer with a misleading "empty region"
            out["p_region"]["model_interval_error"] = (
                "no model interval: " + str(exc).splitlines()[0])
        else:
            out["p_region"]["model_ci"] = model_iv["ci"]
            out["model_interval"] = dict(model_iv)
            out["model_interval"]["replicates_quantiles"] = _quantiles(model_iv["replicates"])
    exp = getattr(model, "exposure_", None)
    if exp:
        rates = region_rates(Exposure.from_dict(exp), p, model_iv, seed=MODEL_SEED,
                             confidence=confidence)
        if n_samples:
            for unit in ("per_hour", "per_1e6_km"):
                if unit in rates:  # each sample's exposure weight in this unit: they sum to it
                    rates[unit]["weight_per_sample"] = rates[unit]["estimate"] / n_samples
        out["rates"] = rates
    return out


def _quantiles(values: Any) -> dict[str, float]:
    """Percentiles 0, 2.5, 10, 50, 90, 97.5, 100 of the replicates' P(A) (finite ones)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    qs = (0.0, 2.5, 10.0, 50.0, 90.0, 97.5, 100.0)
    if not v.size:
        return {}
    return {f"p{q:g}": float(x) for q, x in zip(qs, np.percentile(v, qs), strict=True)}


#: below this hit rate per draw of its plain run, a criticality region's model interval
#: takes the rare path: the replicates' pilot (8,192 draws) would find fewer than ~20 hits
RARE_RATE = 20 / 8192


def model_interval(model: Any, region: Any, *, rare: bool, n_plain: int = 8192,
                   confidence: float = 0.95, per_replicate: bool = False) -> dict[str, Any]:
    """:func:`~sampler.rates.bootstrap_interval.pooled_interval` of the region with
    ``MODEL_SEED``, memoised on the model per region and replicate set (a copy: callers may
    change it).
    ``per_replicate``: rare regions' unresolved replicates each get their own subset-is run
    (resolves the lower end; 0.4-1 s per replicate on the TNO model: for the asynchronous
    catalogue status, not for a request)."""
    boot = model.bootstrap_
    key = ("pooled_interval", region, bool(rare), int(n_plain), float(confidence),
           bool(per_replicate), boot.get("seed"), boot.get("n_boot"),
           len(boot.get("weights", ())))
    found = memoised(model, key, lambda: pooled_interval(
        model, region, MODEL_SEED, rare=rare, n_plain=n_plain, confidence=confidence,
        per_replicate=per_replicate))
    out = copy.deepcopy(found)
    if out["ci"][0] == 0.0 and out.get("lower_resolved", True):
        out["note"] = ("lower end 0: more than the tail share of the replicates put P(A) "
                       "below subset-is's smallest probability (1e-14)")
    return out


def region_report(model: Any, sample_set: Any, n_plain: int = 8192,
                  confidence: float = 0.95) -> dict[str, Any]:
    """``uncertainty_report`` of a sample set drawn from the model (its region, P(A) and
    size)."""
    return uncertainty_report(model, sample_set.p_region, sample_set.region,
                              n_samples=max(1, len(sample_set)), n_plain=n_plain,
                              confidence=confidence)


#: one line each on what the two intervals of P(A) and of a rate mean (issue 25 item 3)
INTERVAL_READINGS = {
    "model": "model interval: where P(A) could lie under another fit equally supported by "
             "the real cut-ins (bootstrap refits): the data's uncertainty, which more "
             "sampling does not narrow",
    "mc": "Monte Carlo interval: the sampler's own uncertainty about P(A) under this one "
          "fitted model: more draws narrow it",
}


def model_wider(fig: Mapping[str, Any]) -> bool:
    """Is the figure's model interval wider than its Monte Carlo one (in ratio of ends, as
    both are on a log scale; an unknown model interval is not wider)?"""
    mc, model = fig.get("mc_ci"), fig.get("model_ci")
    if not mc or not model:
        return False

    def spread(v: Sequence[float]) -> float:
        lo, hi = float(v[0]), float(v[1])
        return math.inf if lo <= 0.0 < hi else (hi / lo if lo > 0 else 1.0)

    return spread(model) > spread(mc)


def report_text(report: Mapping[str, Any]) -> str:
    """One line per figure: P(A) and the rates with both intervals."""
    mi = report.get("model_interval") or {}
    resolved = mi.get("lower_resolved", True)

    def iv(v: Any, model: bool = False, zero: str = "< 1e-14") -> str:
        if v is None:
            return "n/a"
        low = ("lower end not resolved" if model and not resolved
               else zero if model and v[0] == 0.0 else f"{v[0]:.3g}")
        return f"[{low}, {v[1]:.3g}]"

    def both(fig: Mapping[str, Any], zero: str = "< 1e-14") -> str:
        # the wider interval first: it is the one that limits what the figure says
        mc = f"Monte Carlo {iv(fig['mc_ci'])}"
        model = f"model {iv(fig['model_ci'], True, zero)}"
        return f"{model}  {mc}" if model_wider(fig) else f"{mc}  {model}"

    p = report["p_region"]
    lines = [f"P(A) {p['estimate']:.3g}  {both(p)}"]
    rates = report.get("rates")
    if rates:
        for unit, label in (("per_hour", "per hour"), ("per_1e6_km", "per 10^6 km")):
            if rates.get(unit):
                lines.append(f"rate {label} {rates[unit]['estimate']:.3g}  "
                             f"{both(rates[unit], '≈ 0')}")
        e = rates["exposure"]
        lines.append(f"exposure: {e['n_events']} cut-ins in "
                     + " and ".join(x for x in (
                         f"{e['hours']:.4g} h" if e["hours"] else "",
                         f"{e['km']:.4g} km" if e["km"] else "") if x)
                     + f" ({e['source']})")
    if p.get("model_ci"):
        lines.extend(INTERVAL_READINGS[k] for k in (("model", "mc") if model_wider(p)
                                                     else ("mc", "model")))
    if mi.get("note"):
        lines.append("model interval: " + str(mi["note"]))
    return "\n".join(lines)
