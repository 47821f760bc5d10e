"""Samplers of the truncated model: strategy objects with one method, ``draw``.

The target is the model density restricted to a region A (constraints and physical bounds)
and renormalised: ``p(x | A) = p(x) 1_A(x) / P(A)``. ``Problem`` binds a model and a region
and draws from the *proposal*: the model restricted to the region's half-space envelope
(``sampler.methods.envelope``) when there is one, else the whole model.

* ``RejectionSampler`` — exact: draw i.i.d. from the proposal (a numpy Generator that is
  advanced, labels then Gaussians), keep the draws inside A. Every kept draw is an
  independent sample (effective sample size = n).
* ``MCMCSampler`` — emcee's ensemble sampler in the model's z-space (``sampler.methods.mcmc``).
* ``SubsetSampler`` — subset simulation (``sampler.methods.subset``) for rare regions.
* ``SubsetISSampler`` — subset levels to find the region, importance sampling for P(A),
  independence chains for the samples (``sampler.methods.rare``): far cheaper than plain subset
  simulation for the same CoV.
* ``AutoSampler`` — when the pilot found fewer than ``subset_below`` draws inside A (too
  few to start MCMC walkers from or to estimate P(A) by plain MC): ``subset-is`` for
  regions with a criticality constraint (closed-loop simulations: where its economy
  matters), plain subset simulation otherwise (unbiased whatever the region's shape;
  subset-is can miss a mode, see ``sampler.methods.rare``);
  otherwise rejection when its expected cost ``n / p_pilot`` draws is below the MCMC cost
  model ``cost_ratio * (n * tau_guess + n_walkers * burn_guess)`` (a fixed, documented
  rule, so the choice is deterministic), MCMC otherwise.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from sampler.errors import EmptyRegionError, SamplerError
from sampler.intervals import upper95
from sampler.methods.envelope import find_envelope
from sampler.methods.mcmc import MCMCSampler
from sampler.methods.probability import PRegion, PRegionEstimator
from sampler.methods.problem import Draw, Pilot, PilotPlan, Problem, ProgressFn, Run, Sampler
from sampler.methods.rare import SubsetISSampler
from sampler.methods.subset import SubsetSampler
from sampler.model.gmm import CutInGMM
from sampler.region.constraints import Region

__all__ = [
    "SAMPLERS",
    "SAMPLER_NAMES",
    "SPLIT_QUANTITIES",
    "SPLIT_TTC",
    "AutoSampler",
    "Draw",
    "MCMCSampler",
    "Pilot",
    "Problem",
    "ProgressFn",
    "RejectionSampler",
    "Sampler",
    "SubsetISSampler",
    "SubsetSampler",
    "make_sampler",
    "split_parts",
]


def raise_if_pilot_found_nothing(problem: Problem, pilot: Pilot, method: str) -> None:
    """Empty-region check shared by the samplers: when neither the pilot nor its widened
    search found one point inside the region, give up at once (``EmptyRegionError``)
    instead of drawing up to ``max_draws`` (tens of seconds) to find none either. MCMC
    stops on the same evidence (it has no point to start from)."""
    if pilot.n_hits > 0 or pilot.search_hits.size > 0:
        return
    draws = pilot.n_draws + pilot.search_draws
    widened = f" and {pilot.search_draws} widened" if pilot.search_draws else ""
    raise EmptyRegionError(
        f"{method} sampling: none of {pilot.n_draws} pilot draws{widened} fell inside "
        f"{problem.region.describe()}: the region is empty or practically empty (mass "
        f"below about {problem.proposal_mass * upper95(0, max(pilot.n_draws, 1)):.3g})",
        n_draws=draws, n_hits=0,
        p_upper=problem.proposal_mass * upper95(0, max(pilot.n_draws, 1)))


class RejectionSampler(Sampler):
    """Exact rejection sampling from the truncated mixture.

    Parameters
    ----------
    max_draws : int
        Give up (``EmptyRegionError`` with the mass found) after this many model draws.
    min_batch, max_batch : int
        Batch sizes; each batch is sized from the current acceptance estimate.
    """

    name = "rejection"

    def __init__(self, max_draws: int = 50_000_000, min_batch: int = 4096,
                 max_batch: int = 1 << 20) -> None:
        self.max_draws = int(max_draws)
        self.min_batch = int(min_batch)
        self.max_batch = int(max_batch)

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        raise_if_pilot_found_nothing(problem, pilot, self.name)
        kept = [pilot.hits[:n]]
        got = min(pilot.n_hits, n)
        draws, hits = pilot.n_draws, pilot.n_hits
        while got < n:
            if draws >= self.max_draws:
                raise EmptyRegionError(
                    f"rejection sampling found {hits} of {draws} draws inside "
                    f"{problem.region.describe()} (mass about "
                    f"{problem.proposal_mass * hits / max(draws, 1):.3g}); "
                    f"{n} samples would need about {n / max(hits / max(draws, 1), 1e-300):.3g} "
                    "draws: use --sampler mcmc or raise max_draws",
                    n_draws=draws, n_hits=hits,
                    p_upper=problem.proposal_mass * upper95(hits, draws))
            rate = (hits + 1) / (draws + 2)
            batch = int(np.clip(1.2 * (n - got) / rate, self.min_batch, self.max_batch))
            batch = min(batch, self.max_draws - draws)
            z = problem.draw_z(batch, rng)
            inside = problem.inside(z)
            new = z[inside]
            draws += batch
            hits += new.shape[0]
            take = new[: n - got]
            kept.append(take)
            got += take.shape[0]
            if progress is not None:
                progress("rejection", got, n)
        z_all = np.concatenate(kept, axis=0)
        return Draw(z=z_all, method=self.name,
                    diagnostics={"n_draws": draws, "n_hits": hits,
                                 "acceptance_rate": hits / draws if draws else 0.0,
                                 "envelope": (problem.envelope.to_dict()
                                              if problem.envelope is not None else None),
                                 "ess": float(n), "n_evaluations": problem.n_evals},
                    mc_draws=draws, mc_hits=hits)

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        d = diagnostics
        return [f"acceptance {d['acceptance_rate']:.3g} of {d['n_draws']} draws"]



class AutoSampler(Sampler):
    """Pick rejection or MCMC from the pilot's mass estimate (deterministic cost rule).

    Parameters
    ----------
    cost_ratio : float
        Cost of one MCMC log-probability evaluation relative to one rejection draw
        (measured on this code: evaluations carry emcee's per-step overhead and the
        kinematics for every walker, rejection draws mostly fail the cheap tests).
    tau_guess, burn_guess : float
        Assumed autocorrelation time and burn-in, in steps.
    subset_below : int
        Fewer pilot hits than this choose ``rare`` for criticality regions, ``subset``
        otherwise (default: the MCMC walkers).
    rare, subset : Sampler
        The rare-region samplers (defaults ``SubsetISSampler``, ``SubsetSampler``;
        measured in ``benchmarks/bench_rare.py``).
    """

    name = "auto"

    def __init__(self, rejection: RejectionSampler | None = None,
                 mcmc: MCMCSampler | None = None, cost_ratio: float = 50.0,
                 tau_guess: float = 30.0, burn_guess: float = 600.0,
                 rare: Sampler | None = None, subset: Sampler | None = None,
                 subset_below: int | None = None) -> None:
        self.rejection = rejection or RejectionSampler()
        self.mcmc = mcmc or MCMCSampler()
        self.rare = rare or SubsetISSampler()
        self.subset = subset or SubsetSampler()
        self.subset_below = int(self.mcmc.n_walkers if subset_below is None else subset_below)
        self.cost_ratio = float(cost_ratio)
        self.tau_guess = float(tau_guess)
        self.burn_guess = float(burn_guess)

    def choose(self, n: int, pilot: Pilot, costly: bool = False) -> Sampler:
        """The sampler for ``n`` samples given the pilot; ``costly``: the region has a
        criticality constraint."""
        if pilot.n_hits >= n and (pilot.plain or pilot.n_hits >= self.subset_below):
            # the pilot's exact hits are the samples: rejection costs nothing more (a thin
            # band's extended pilot, a plain run, holds ~100 hits from 2e7 draws; the cost
            # rule below would have chosen MCMC, 150 s of simulated chains, for 20 samples)
            return self.rejection
        if costly and pilot.plain and pilot.n_hits > 0:
            # the pilot's plain run holds P(A) already; more exact draws by rejection
            # are cheap when btn_bound rules out nearly every draw without a simulation
            # (MCMC chains in such a region were measured to run for many minutes), and
            # subset-is makes the samples when rejection would need too many draws
            if n / pilot.p_hat <= self.rejection.max_draws:
                return self.rejection
            return self.rare
        if pilot.n_hits < self.subset_below:
            return self.rare if costly else self.subset
        rej_cost = n / pilot.p_hat
        mcmc_cost = self.cost_ratio * (n * self.tau_guess
                                       + self.mcmc.n_walkers * self.burn_guess)
        if rej_cost <= mcmc_cost and rej_cost <= self.rejection.max_draws:
            return self.rejection
        return self.mcmc

    def pilot_plan(self, problem: Problem) -> PilotPlan:
        """No pilot hit: the broadened search (which ends empty regions); few: subset(-is).
        Not for criticality regions (10^5-10^6 simulations; subset-is ends empty ones).
        Criticality regions get the extended pilot (``PRegionEstimator.extend_pilot``)."""
        return PilotPlan(need=0 if problem.costly else 1, extend=True)

    def prepare(self, run: Run, n: int, pilot: Pilot) -> None:
        """When the choice is MCMC: a starting point per walker (the broadened search)."""
        if self.choose(n, pilot, run.problem.costly) is self.mcmc:
            run.estimator.search(run.problem, run.rng, pilot, self.mcmc.n_walkers)

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        chosen = self.choose(n, pilot, problem.costly)
        out = chosen.draw(problem, n, rng, pilot, progress)
        out.diagnostics["auto"] = {"p_pilot": pilot.p_hat, "chosen": chosen.name,
                                   "cost_ratio": self.cost_ratio,
                                   "tau_guess": self.tau_guess, "burn_guess": self.burn_guess}
        return out

    def _chosen(self, drawn: Draw) -> Sampler:
        """The sampler that made ``drawn`` (by its name)."""
        for s in (self.rejection, self.mcmc, self.rare, self.subset):
            if s.name == drawn.method:
                return s
        raise SamplerError(f"auto: no sampler of its own is named {drawn.method!r}")

    def estimate_p(self, run: Run, pilot: Pilot, drawn: Draw) -> PRegion:
        """P(A): the extended pilot's plain run alone when it has one (exact, unbiased; the
        draws rejection adds were continued until enough hits, which would bias it); the
        sum of two parts (``split_parts``) when a rare-event method made the samples of a
        region split at the envelope; else the chosen sampler's estimate."""
        if pilot.plain and pilot.n_hits > 0:
            return run.estimator.estimate(run.problem, run.rng, mc_draws=pilot.n_draws,
                                          mc_hits=pilot.n_hits, region_z=pilot.hits,
                                          bounds=run.bounds, plain=True)
        parts = (split_parts(run.problem.region)
                 if drawn.subset is not None and not pilot.plain else None)
        if parts is not None:
            # P(A) as estimate_p_region gives it, from the two parts; the samples are still
            # those of the whole region's subset-is run
            p_region, info = self.split_estimate(run, parts)
            drawn.diagnostics["split"] = {
                "parts": info, "whole_region_estimate": float(drawn.subset.probability),
                "note": f"P(A) is the sum of two parts estimated apart (ttc < {SPLIT_TTC:g} "
                        "and the rest); the samples come from one subset-is run over the "
                        "whole region, which may under-represent the part outside ttc < 3"}
            return p_region
        return self._chosen(drawn).estimate_p(run, pilot, drawn)

    def estimate_alone(self, run: Run, pilot: Pilot) -> PRegion:
        """P(A) without samples, given the pilot: its plain Monte Carlo when it found
        enough hits; with fewer than ``subset_below`` (as ``choose``) subset simulation,
        or for criticality regions the split (``split_parts``) or subset-is; otherwise a
        short MCMC run supplies the importance sampler's proposal."""
        est = run.estimator
        if pilot.n_hits >= est.mc_min_hits or (pilot.plain and pilot.n_hits > 0):
            return est.estimate(run.problem, run.rng, mc_draws=pilot.n_draws,
                                mc_hits=pilot.n_hits, region_z=pilot.hits, bounds=run.bounds,
                                plain=pilot.plain)
        if pilot.n_hits < self.subset_below:
            if not run.problem.costly:
                return self.subset.estimate_alone(run, pilot)
            parts = split_parts(run.problem.region)
            if parts is not None:
                return self.split_estimate(run, parts)[0]
            return self.rare.estimate_alone(run, pilot)
        return self.mcmc.estimate_alone(run, pilot)

    def estimate_region(self, model: CutInGMM, region: Region, seed: int,
                        estimator: PRegionEstimator,
                        progress: ProgressFn | None = None) -> PRegion:
        """P(A) of a region (bound to ``model``) without samples: P(B), the extended
        pilot, then ``estimate_alone`` (``sampler.estimate_p_region``)."""
        rng = np.random.default_rng(seed)
        problem = Problem(model, region)
        run = Run(problem, rng, estimator, estimator.p_bounds(problem, rng), seed, progress)
        pilot = estimator.pilot(problem, rng, need=0, progress=progress, extend=True)
        return self.estimate_alone(run, pilot)

    def split_estimate(self, run: Run, parts: list[Region]
                       ) -> tuple[PRegion, list[dict[str, Any]]]:
        """P(A) as the sum of its parts' estimates (``PRegionEstimator.combine``), each from
        ``estimate_region`` with its own seed derived from the run's; and the parts'
        figures for the diagnostics. A part found empty counts with its upper bound as its
        error (its ``EmptyRegionError`` is raised when the levels stalled, so that the bound
        is not reliable, or when every part is empty)."""
        est, bounds = run.estimator, run.bounds
        out: list[PRegion] = []
        info: list[dict[str, Any]] = []
        empty: list[EmptyRegionError] = []
        for k, part in enumerate(parts):
            child = int(np.random.SeedSequence([run.seed, 12, k]).generate_state(1, np.uint64)[0])
            child %= 2**63
            try:
                p = self.estimate_region(run.problem.model, part, child, est, run.progress)
            except EmptyRegionError as exc:
                if exc.stalled is not None or not math.isfinite(exc.p_upper):
                    raise
                empty.append(exc)
                p = PRegion(estimate=0.0, ci_low=0.0,
                            ci_high=min(1.0, exc.p_upper / bounds[0]),
                            confidence=est.confidence, method="empty", n_draws=exc.n_draws,
                            n_hits=0, p_bounds=bounds[0], p_bounds_ci=(bounds[1], bounds[2]),
                            p_joint=0.0)
            out.append(p)
            info.append({"constraints": part.describe(), "seed": child, **p.to_dict()})
        if len(empty) == len(parts):
            raise empty[-1]
        return est.combine(out, bounds), info

    def settings(self) -> dict[str, Any]:
        return {"name": self.name, "cost_ratio": self.cost_ratio, "tau_guess": self.tau_guess,
                "burn_guess": self.burn_guess, "rejection": self.rejection.settings(),
                "mcmc": self.mcmc.settings(), "rare": self.rare.settings(),
                "subset": self.subset.settings(),
                "subset_below": self.subset_below}


#: A region whose criticality constraints are all on ``SPLIT_QUANTITIES`` and which has
#: no half-space envelope (no kinematic constraint such as ``ttc<3``) is estimated in two
#: parts split at this TTC when the pilot finds too few hits: inside the
#: ``ttc < SPLIT_TTC`` envelope (plain Monte Carlo there, exact, when its budget allows)
#: and outside it (subset-is). ``btn`` has a second route outside it (the cutter brakes
#: after a cut-in at a safe TTC) that subset-is over the whole region under-represents:
#: its intervals covered 5-8 of 10 seeds, the split's 10 of 10. On ``ttr_true`` the split
#: cost 3x the simulations and its outside part's levels can fail to converge, so it is
#: not used there (docs/sampler.md, "Standalone `btn` regions: split at the envelope").
SPLIT_TTC = 3.0
SPLIT_QUANTITIES = frozenset({"btn", "a_req"})


def split_parts(region: Region) -> list[Region] | None:
    """The two parts of a region ``auto`` estimates apart (see ``SPLIT_TTC``), or None
    when it is not such a region: a criticality constraint not on ``SPLIT_QUANTITIES``
    (or none), a constraint on ``ttc`` already, or no half-space envelope for
    ``ttc < SPLIT_TTC`` (the model lacks gap/dv)."""
    critical = {c.name for c in region.constraints if c.tier == 2}
    if not critical or not critical <= SPLIT_QUANTITIES:
        return None
    if any(c.name == "ttc" for c in region.constraints):
        return None
    model = region._model
    if model is None:
        return None
    if find_envelope(model, region) is not None:
        return None
    parts = [Region.from_constraints([*region.constraints, extra],
                                     lane_width=region.lane_width,
                                     physical_bounds=region.physical_bounds).bind(model)
             for extra in (f"ttc<{SPLIT_TTC:g}", f"ttc>={SPLIT_TTC:g}")]
    return parts if find_envelope(model, parts[0]) is not None else None


#: the one list of the samplers, by name: the CLI's ``--sampler`` choices, the API's
#: ``sampler`` field and the catalogues' check are derived from it (``SAMPLER_NAMES``)
SAMPLERS: dict[str, type[Sampler]] = {"auto": AutoSampler, "rejection": RejectionSampler,
                                      "mcmc": MCMCSampler, "subset": SubsetSampler,
                                      "subset-is": SubsetISSampler}
SAMPLER_NAMES: tuple[str, ...] = tuple(SAMPLERS)


def make_sampler(method: str | Sampler) -> Sampler:
    """A Sampler from its name (``auto``, ``rejection``, ``mcmc``, ``subset``,
    ``subset-is``) or pass one through."""
    if isinstance(method, Sampler):
        return method
    if method not in SAMPLERS:
        raise SamplerError(f"sampler: unknown method {method!r}; valid: {', '.join(SAMPLERS)}")
    return SAMPLERS[method]()
