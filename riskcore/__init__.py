"""riskcore: Monte-Carlo time-to-react risk (Wagner et al.). Pure numerics.

Public surface:

- :func:`evaluate_scene` (ego future + objects' states → :class:`SceneResult`) and
  :func:`evaluate_scenario` (concrete scenario → :class:`ScenarioRisk`).
- :class:`RiskSettings` (Table II, ego capabilities), :class:`InputSurfaces` (eq. 2).
- Building blocks: :func:`ctra_states`, :func:`boxes_overlap`, :func:`ttc_constant_velocity`,
  :func:`time_headway`, :func:`ttr_weight`, :func:`risk_dependent`,
  :func:`risk_independent`, :func:`input_grid`, the manoeuvres.
- The interchange type :class:`ConcreteScenario` (with :class:`Track`) and the errors.
"""

from riskcore.ctra import ctra_states
from riskcore.errors import FieldError, RiskcoreError, SceneError, SettingsError, SurfaceError
from riskcore.evasion import (
    MANOEUVRES,
    Accelerate,
    Brake,
    Manoeuvre,
    Steer,
    evasion_label,
    evasion_names,
)
from riskcore.geometry import boxes_overlap, time_headway, ttc_constant_velocity
from riskcore.risk import object_risk, risk_dependent, risk_independent, ttr_weight
from riskcore.sampling import input_grid, standard_grid
from riskcore.scenario import ConcreteScenario, ScenarioError, Track
from riskcore.scenario_risk import (
    RESULT_FORMAT,
    ScenarioRisk,
    ego_future_at,
    evaluate_scenario,
    object_inputs,
)
from riskcore.scene import EgoFuture, ObjectRisk, ObjectState, SceneResult, evaluate_scene
from riskcore.settings import RiskSettings
from riskcore.surfaces import FORMAT as SURFACES_FORMAT
from riskcore.surfaces import InputSurfaces, Surface

__all__ = [
    "MANOEUVRES",
    "RESULT_FORMAT",
    "SURFACES_FORMAT",
    "Accelerate",
    "Brake",
    "ConcreteScenario",
    "EgoFuture",
    "FieldError",
    "InputSurfaces",
    "Manoeuvre",
    "ObjectRisk",
    "ObjectState",
    "RiskSettings",
    "RiskcoreError",
    "ScenarioError",
    "ScenarioRisk",
    "SceneError",
    "SceneResult",
    "SettingsError",
    "Steer",
    "Surface",
    "SurfaceError",
    "Track",
    "boxes_overlap",
    "ctra_states",
    "ego_future_at",
    "evaluate_scenario",
    "evaluate_scene",
    "evasion_label",
    "evasion_names",
    "input_grid",
    "object_inputs",
    "object_risk",
    "risk_dependent",
    "risk_independent",
    "standard_grid",
    "time_headway",
    "ttc_constant_velocity",
    "ttr_weight",
]
