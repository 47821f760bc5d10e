"""riskcore: Monte-Carlo time-to-react risk (Wagner et al.). Pure numerics."""

from riskcore.scenario import ConcreteScenario, ScenarioError, Track

__all__ = ["ConcreteScenario", "ScenarioError", "Track"]
