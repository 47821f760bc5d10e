"""The scenario: a parameter vector made concrete and scored.

- :mod:`~sampler.scenario.builder` — vector -> :class:`~riskcore.scenario.ConcreteScenario`
  (and the builder's constants: lead-in, time step, vehicle size);
- :mod:`~sampler.scenario.batch` — many vectors -> the scripted world of a closed-loop
  batch (``riskcore.sut.CutInBatch``), the builder's tracks without building scenarios;
- :mod:`~sampler.scenario.record` — vector -> scenario -> scored
  :class:`ScenarioRecord`: the one join of sampler and riskcore;
- :mod:`~sampler.scenario.scoring` — many vectors, in parts, on an executor the caller
  gives (sampler starts no processes).
"""

from sampler.scenario.batch import (
    CutInTracks,
    buildable_batch,
    buildable_batches,
    cutin_batch,
    cutin_tracks,
)
from sampler.scenario.builder import (
    DEFAULT_DT,
    DEFAULT_HORIZON,
    DEFAULT_LEAD_IN,
    DEFAULT_VEHICLE_SIZE,
    build_scenario,
)
from sampler.scenario.record import (
    SCORE_FIELDS,
    SUPPORT_FIELDS,
    OutsideParameter,
    ScenarioRecord,
    score_rows,
    score_vector,
)
from sampler.scenario.scoring import score_part, score_samples

__all__ = [
    "DEFAULT_DT",
    "DEFAULT_HORIZON",
    "DEFAULT_LEAD_IN",
    "DEFAULT_VEHICLE_SIZE",
    "SCORE_FIELDS",
    "SUPPORT_FIELDS",
    "CutInTracks",
    "OutsideParameter",
    "ScenarioRecord",
    "build_scenario",
    "buildable_batch",
    "buildable_batches",
    "cutin_batch",
    "cutin_tracks",
    "score_part",
    "score_rows",
    "score_samples",
    "score_vector",
]
