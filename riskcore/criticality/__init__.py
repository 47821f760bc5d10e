"""Criticality of a cut-in: margins at the perception moment, reacting reference drivers.

The semantics for test engineers are in docs/criticality.md; the contract is the flat field
names of ``CRITICALITY_FIELDS``. The parts:

- :mod:`~riskcore.criticality.evaluate` — :func:`evaluate_criticality`, one record per
  concrete scenario, and the semantics (module docstring);
- :mod:`~riskcore.criticality.record` — the settings, the fields and the classes;
- :mod:`~riskcore.criticality.drivers` — frames, t_p, the crossing, the reference drivers;
- :mod:`~riskcore.criticality.wagner` — Wagner's risk along the scenario;
- :mod:`~riskcore.criticality.kernels` — the compiled kernels (ego frame), public for batch
  use: sampler evaluates the same quantities straight from parameter vectors with them.
"""

from riskcore.criticality.drivers import conflict_resolution, crossing_time, perception_time
from riskcore.criticality.evaluate import evaluate_criticality
from riskcore.criticality.record import (
    CLASSES,
    CRITICALITY_FIELDS,
    Criticality,
    CriticalityError,
    CriticalitySettings,
    FieldSpec,
    G,
    settings_from_dict,
)
from riskcore.criticality.wagner import criticality_profiles

__all__ = [
    "CLASSES",
    "CRITICALITY_FIELDS",
    "Criticality",
    "CriticalityError",
    "CriticalitySettings",
    "FieldSpec",
    "G",
    "conflict_resolution",
    "criticality_profiles",
    "crossing_time",
    "evaluate_criticality",
    "perception_time",
    "settings_from_dict",
]
