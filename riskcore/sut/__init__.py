"""Systems under test: a protocol for whatever drives the ego, one closed-loop simulator
vectorised over N cut-ins, built-in SUTs and the regulation's verdict (docs/systems.md).

- :mod:`~riskcore.sut.batch` — :class:`CutInBatch` (the scripted world of N runs) and
  :class:`Observations` (what a SUT perceives at one step);
- :mod:`~riskcore.sut.protocol` — :class:`SystemUnderTest`, :class:`PerRunSUT`,
  :func:`per_run`;
- :mod:`~riskcore.sut.settings` — :class:`SimSettings`;
- :mod:`~riskcore.sut.simulate` — :func:`simulate`;
- :mod:`~riskcore.sut.runs` — :class:`RunBatch`, :data:`RUN_FIELDS`,
  :func:`compare_careful`;
- :mod:`~riskcore.sut.suts` — :data:`BUILTIN_SUTS`, :func:`make_sut`;
- :mod:`~riskcore.sut.regulation` — :func:`must_avoid` (UN R157 5.2.5.2 / EU 2022/1426);
- :mod:`~riskcore.sut.kernels` — the compiled kernels; public of them, for a simulator
  that steps the ego itself (app.esmini): the ego's vehicle model :func:`ego_advance`,
  :func:`ego_advance_with_onset` and the box geometry :func:`band_range`,
  :func:`box_clearance`.
"""

from riskcore.sut.batch import CutInBatch, Observation, Observations
from riskcore.sut.errors import SutError
from riskcore.sut.kernels import band_range, box_clearance, ego_advance, ego_advance_with_onset
from riskcore.sut.protocol import PerRunSUT, SystemUnderTest, per_run
from riskcore.sut.regulation import MUST_AVOID_VARIANTS, must_avoid, must_avoid_ttc
from riskcore.sut.runs import RUN_FIELDS, RunBatch, RunField, compare_careful
from riskcore.sut.settings import SimSettings
from riskcore.sut.simulate import simulate
from riskcore.sut.suts import BUILTIN_SUTS, SutSpec, make_sut

__all__ = [
    "BUILTIN_SUTS",
    "MUST_AVOID_VARIANTS",
    "RUN_FIELDS",
    "CutInBatch",
    "Observation",
    "Observations",
    "PerRunSUT",
    "RunBatch",
    "RunField",
    "SimSettings",
    "SutError",
    "SutSpec",
    "SystemUnderTest",
    "band_range",
    "box_clearance",
    "compare_careful",
    "ego_advance",
    "ego_advance_with_onset",
    "make_sut",
    "must_avoid",
    "must_avoid_ttc",
    "per_run",
    "simulate",
]
