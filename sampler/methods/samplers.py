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

from typing import Any

import numpy as np

from sampler.errors import EmptyRegionError, SamplerError
from sampler.intervals import upper95
from sampler.methods.mcmc import MCMCSampler, _tau
from sampler.methods.problem import Draw, Pilot, Problem, ProgressFn, Sampler
from sampler.methods.rare import SubsetISSampler
from sampler.methods.subset import SubsetSampler

__all__ = [
    "SAMPLERS",
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
    "_tau",
    "make_sampler",
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

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        costly = any(c.tier == 2 for c in problem.region.constraints)
        chosen = self.choose(n, pilot, costly)
        out = chosen.draw(problem, n, rng, pilot, progress)
        out.diagnostics["auto"] = {"p_pilot": pilot.p_hat, "chosen": chosen.name,
                                   "cost_ratio": self.cost_ratio,
                                   "tau_guess": self.tau_guess, "burn_guess": self.burn_guess}
        return out

    def settings(self) -> dict[str, Any]:
        return {"name": self.name, "cost_ratio": self.cost_ratio, "tau_guess": self.tau_guess,
                "burn_guess": self.burn_guess, "rejection": self.rejection.settings(),
                "mcmc": self.mcmc.settings(), "rare": self.rare.settings(),
                "subset": self.subset.settings(),
                "subset_below": self.subset_below}


SAMPLERS: dict[str, type[Sampler]] = {"auto": AutoSampler, "rejection": RejectionSampler,
                                      "mcmc": MCMCSampler, "subset": SubsetSampler,
                                      "subset-is": SubsetISSampler}


def make_sampler(method: str | Sampler) -> Sampler:
    """A Sampler from its name (``auto``, ``rejection``, ``mcmc``, ``subset``,
    ``subset-is``) or pass one through."""
    if isinstance(method, Sampler):
        return method
    if method not in SAMPLERS:
        raise SamplerError(f"sampler: unknown method {method!r}; valid: {', '.join(SAMPLERS)}")
    return SAMPLERS[method]()
