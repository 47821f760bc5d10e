"""The sampling problem and the samplers' common interface.

``Problem`` binds a fitted model and a region (membership, log-probability and the
proposal draws in the model's z-space); ``Pilot`` holds the plain Monte-Carlo draws made
before sampling; ``Draw`` is what every sampler returns; ``Sampler`` is the strategy
interface: ``draw`` and the hooks ``sampler.sample`` asks instead of checking which sampler
it holds (``pilot_plan``: what pilot it needs; ``prepare``: anything between the pilot and
``draw``; ``estimate_p``: P(A) for its draw; ``summarise``: its part of the summary line).
A ``Run`` carries what the hooks share (the problem, the generator, the P(A) estimator,
P(B), the seed). The strategies live in ``sampler.methods.samplers`` (rejection, auto),
``sampler.methods.mcmc`` (emcee), ``sampler.methods.subset`` and ``sampler.methods.rare``.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from sampler.methods.envelope import HalfSpace, find_envelope
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region

if TYPE_CHECKING:  # probability builds on this module
    from sampler.methods.probability import PRegion, PRegionEstimator

__all__ = ["BoolArray", "Draw", "FloatArray", "Pilot", "PilotPlan", "Problem", "ProgressFn",
           "Run", "Sampler"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: progress callback: (stage, done, total)
ProgressFn = Callable[[str, int, int], None]


class Problem:
    """A fitted model and a region: membership and log-probability in the model's z-space.

    With ``use_envelope`` (default), the tightest half-space envelope S of the region
    (``sampler.methods.envelope``) is found; then ``draw_z`` draws exactly from the model
    restricted to S instead of the whole model (same target after rejection, fewer misses).
    """

    def __init__(self, model: CutInGMM, region: Region, use_envelope: bool = True) -> None:
        model.check_fitted()
        self.model = model
        self.region = region.bind(model)  # the model quantities use the model (if unbound)
        self.n_evals = 0
        self.envelope: HalfSpace | None = (find_envelope(model, self.region) if use_envelope
                                           else None)

    def draw_z(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` exact draws of the proposal: the model restricted to the envelope, or the
        whole model when there is none."""
        if self.envelope is not None:
            return self.envelope.sample_z(self.model, n, rng)
        return self.model.sample_z(n, rng)

    @property
    def proposal_mass(self) -> float:
        """Model mass of what ``draw_z`` draws from (P(S), or 1)."""
        return self.envelope.mass if self.envelope is not None else 1.0

    @property
    def costly(self) -> bool:
        """Whether the region has a criticality constraint (closed-loop simulations)."""
        return any(c.tier == 2 for c in self.region.constraints)

    @property
    def ndim(self) -> int:
        return self.model.n_features

    def params(self, z: FloatArray) -> FloatArray:
        """Full parameter vectors (n, 8) from z-space rows (n, d)."""
        return self.model.params_matrix(self.model.from_z(z))

    def inside(self, z: FloatArray) -> BoolArray:
        """Rows of z (n, d) inside the region."""
        self.n_evals += z.shape[0]
        return self.region.contains(self.params(z))

    def in_bounds(self, z: FloatArray) -> BoolArray:
        return self.region.in_bounds(self.params(z))

    def log_prob(self, z: FloatArray) -> FloatArray:
        """emcee's vectorised log-probability: log p_z(z) inside the region, -inf outside."""
        z = np.atleast_2d(z)
        out = np.full(z.shape[0], -np.inf)
        ok = np.isfinite(z).all(axis=1)
        idx = np.flatnonzero(ok)
        if idx.size:
            inside = self.inside(z[idx])
            keep = idx[inside]
            if keep.size:
                out[keep] = self.model.log_density_z(z[keep])
        return out


@dataclass
class Draw:
    """What a sampler returns.

    Attributes
    ----------
    z : ndarray of shape (n, d)
        Samples in the model's z-space, all inside the region.
    method : str
        ``"rejection"`` or ``"mcmc"``.
    diagnostics : dict
        JSON-able; always has ``ess`` (effective sample size of ``z``) and ``n_evaluations``.
    mc_draws, mc_hits : int
        Plain model draws made and how many fell inside (usable for P(A)).
    subset : SubsetResult, optional
        Subset simulation's result (``sampler.methods.subset``), which then gives P(A).
    """

    z: FloatArray
    method: str
    diagnostics: dict[str, Any] = field(default_factory=dict)
    mc_draws: int = 0
    mc_hits: int = 0
    subset: Any = None


@dataclass
class Pilot:
    """Plain Monte-Carlo draws made before sampling (exact draws; reused by the samplers)."""

    n_draws: int
    hits: FloatArray  # (k, d) z-space, inside the region, in draw order
    search_hits: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    search_draws: int = 0
    n_simulated: int = 0  # rows simulated (criticality regions: inside the kinematic part)
    probe_draws: int = 0  # the extended pilot's probe (not in n_draws when plain)
    plain: bool = False  # n_draws / hits are a plain run of a size fixed in advance

    @property
    def n_hits(self) -> int:
        return int(self.hits.shape[0])

    @property
    def p_hat(self) -> float:
        return self.n_hits / self.n_draws if self.n_draws else 0.0


@dataclass(frozen=True)
class PilotPlan:
    """What pilot a sampler needs before ``draw`` (``PRegionEstimator.pilot``).

    Attributes
    ----------
    need : int
        Points inside the region ``draw`` starts from: when the plain pilot finds fewer,
        the broadened search looks for the rest (and ends an empty region). 0: none.
    extend : bool
        Extend the pilot of a criticality region into a plain Monte-Carlo run when its
        budget allows (``PRegionEstimator.extend_pilot``).
    """

    need: int = 0
    extend: bool = False


@dataclass
class Run:
    """What the hooks of one ``sample`` (or ``estimate_p_region``) call share."""

    problem: Problem
    rng: np.random.Generator
    estimator: PRegionEstimator
    bounds: tuple[float, float, float]  # P(B) and its interval
    seed: int
    progress: ProgressFn | None = None

    def starting(self, stage: str) -> None:
        """Tell ``progress`` that a stage starts (without counts)."""
        if self.progress is not None:
            self.progress(stage, 0, 1)


class Sampler(ABC):
    """Strategy: draw ``n`` samples of the truncated model given the pilot's draws.

    ``sampler.sample`` asks the strategy, never its type: ``pilot_plan`` (the pilot it
    needs), ``prepare`` (between the pilot and ``draw``), ``draw``, ``estimate_p`` (P(A)
    for its draw) and, for a stored set, ``summarise`` (by its ``name``). The defaults fit
    a sampler that needs no pilot point and whose draws are the model's plain draws."""

    name: str = "abstract"

    @abstractmethod
    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        """Return ``n`` samples inside the region (advancing ``rng``)."""

    def pilot_plan(self, problem: Problem) -> PilotPlan:
        """The pilot ``draw`` needs (default: no point, not extended)."""
        return PilotPlan()

    def prepare(self, run: Run, n: int, pilot: Pilot) -> None:  # noqa: B027 - a hook
        """Anything between the pilot and ``draw`` (default: nothing)."""

    def estimate_p(self, run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
        """P(A) for ``drawn`` (default: plain Monte Carlo over the model draws it made, or
        importance sampling when they hit too rarely: ``PRegionEstimator.estimate``)."""
        return run.estimator.estimate(run.problem, run.rng, mc_draws=drawn.mc_draws,
                                      mc_hits=drawn.mc_hits, region_z=drawn.z,
                                      bounds=run.bounds, plain=pilot.plain)

    def estimate_alone(self, run: Run, pilot: Pilot) -> PRegion:
        """P(A) without samples, given the pilot (``sampler.estimate_p_region``; default:
        plain Monte Carlo over the pilot's draws, or importance sampling around its hits)."""
        return run.estimator.estimate(run.problem, run.rng, mc_draws=pilot.n_draws,
                                      mc_hits=pilot.n_hits, region_z=pilot.hits,
                                      bounds=run.bounds, plain=pilot.plain)

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        """The summary line's parts about a draw of this sampler (``SampleSet.summary``)."""
        return [f"ESS {diagnostics['ess']:.0f}"] if "ess" in diagnostics else []

    def settings(self) -> dict[str, Any]:
        """JSON-able settings, stored with the sample set."""
        return {"name": self.name, **{k: v for k, v in vars(self).items()
                                      if not k.startswith("_")}}

