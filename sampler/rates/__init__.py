"""The rates: how often a region's cut-ins happen, with both intervals.

- :mod:`~sampler.rates.exposure` — a data set's exposure (hours, km, cut-ins) and the
  rates of a region per hour and per 10^6 km;
- :mod:`~sampler.rates.bootstrap_interval` — the "model" interval of P(A) from the bootstrap
  replicates.
"""

from sampler.rates.bootstrap_interval import INTERVALS, bootstrap_ci, pooled_interval
from sampler.rates.exposure import (
    TNO_HOURS,
    Exposure,
    cutin_rate,
    highd_exposure,
    model_interval,
    region_rates,
    region_report,
    report_text,
    tno_exposure,
    uncertainty_report,
)

__all__ = [
    "INTERVALS",
    "TNO_HOURS",
    "Exposure",
    "bootstrap_ci",
    "cutin_rate",
    "highd_exposure",
    "model_interval",
    "pooled_interval",
    "region_rates",
    "region_report",
    "report_text",
    "tno_exposure",
    "uncertainty_report",
]
