"""The MCMC sampler: emcee's ensemble sampler on the truncated model in z-space.

``MCMCSampler`` runs emcee's ``EnsembleSampler`` with a vectorised log-probability
(``log p_z(z)``, -inf outside A); moves ``DEMove`` 0.4, ``DESnookerMove`` 0.1 and an
independence ``MHMove`` 0.5 (proposal: the envelope, or a defensive Gaussian-mixture fit);
walkers started at distinct points inside A (exact draws found by the pilot, or by the
broadened search); it runs in chunks until the chain is at least ``min_tau_multiple``
integrated autocorrelation times long and holds ``n`` thinned post-burn-in samples (burn-in
``ceil(2 tau)``, thinning ``ceil(tau)``), or until ``max_steps``. emcee draws from its own
``RandomState``, seeded from our Generator through its ``random_state`` property (emcee 3.1
has no seed argument), so the same seed gives the same chain. Diagnostics: acceptance
fraction per walker, tau per feature, effective sample size.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import emcee
import numpy as np
from scipy.special import logsumexp

from sampler.errors import EmptyRegionError, SamplerError
from sampler.intervals import upper95
from sampler.methods.problem import (
    Draw,
    FloatArray,
    Pilot,
    PilotPlan,
    Problem,
    ProgressFn,
    Run,
    Sampler,
)
from sampler.model.gmm import CutInGMM

if TYPE_CHECKING:  # annotations only (probability builds on this module)
    from sampler.methods.probability import PRegion

__all__ = ["MCMCSampler", "integrated_time"]


class MixtureProposal:
    """Defensive independence proposal ``q = alpha p + (1 - alpha) g``.

    ``g`` is a Gaussian mixture fitted to points inside the region (scikit-learn, K by BIC
    over 1 ... ``max_k``, covariances inflated by ``inflate**2``) and ``p`` the model itself
    (weight ``alpha``). The model component bounds the importance ratio
    ``p(x | A) / q(x) <= 1 / (alpha P(A))``, so the independence chain is uniformly
    ergodic even where ``g`` has lighter tails than the target. Used as emcee's
    ``MHMove(proposal_function)``: it draws with emcee's RandomState and returns
    ``log q(x) - log q(x')``, the Metropolis-Hastings correction of an independence
    proposal.
    """

    def __init__(self, model: CutInGMM, points: FloatArray, seed: int, max_k: int = 3,
                 inflate: float = 1.3, alpha: float = 0.1) -> None:
        from sklearn.mixture import GaussianMixture

        n, d = points.shape
        best = None
        for k in range(1, max(1, min(max_k, n // (2 * d + 2))) + 1):
            gm = GaussianMixture(k, covariance_type="full", reg_covar=1e-6,
                                 random_state=seed, max_iter=200)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a ConvergenceWarning changes nothing here
                gm.fit(points)
            bic = gm.bic(points)
            if best is None or bic < best[0]:
                best = (bic, gm)
        assert best is not None
        gm = best[1]
        self.model = model
        self.alpha = float(alpha)
        self.k = int(gm.n_components)
        self.weights = np.asarray(gm.weights_, dtype=np.float64)
        self.cdf = np.cumsum(self.weights)
        self.cdf[-1] = 1.0
        self.means = np.asarray(gm.means_, dtype=np.float64)
        covs = np.asarray(gm.covariances_, dtype=np.float64) * inflate**2
        self.chol = np.linalg.cholesky(covs)
        self.chol_inv = np.stack([np.linalg.inv(c) for c in self.chol])
        self.log_norm = (np.log(self.weights) - 0.5 * d * math.log(2 * math.pi)
                         - np.log(np.diagonal(self.chol, axis1=1, axis2=2)).sum(axis=1))

    def describe(self) -> dict[str, Any]:
        return {"kind": "defensive-gaussian-mixture", "components": self.k,
                "alpha": self.alpha}

    def log_q(self, x: FloatArray) -> FloatArray:
        comp = np.empty((self.k, x.shape[0]))
        for k in range(self.k):
            y = (x - self.means[k]) @ self.chol_inv[k].T
            comp[k] = self.log_norm[k] - 0.5 * np.einsum("ij,ij->i", y, y)
        log_g = logsumexp(comp, axis=0)
        log_p = self.model.log_density_z(x)
        return np.asarray(np.logaddexp(math.log(self.alpha) + log_p,
                                       math.log1p(-self.alpha) + log_g), dtype=np.float64)

    def draw(self, n: int, random: np.random.Generator | np.random.RandomState) -> FloatArray:
        """``n`` draws of q (``random``: a Generator or emcee's RandomState)."""
        d = self.means.shape[1]
        from_model = random.random(n) < self.alpha
        labels = np.minimum(np.searchsorted(self.cdf, random.random(n), side="right"),
                            self.k - 1)
        e = random.standard_normal((n, d))
        new = np.empty((n, d))
        for k in range(self.k):
            idx = (labels == k) & ~from_model
            new[idx] = self.means[k] + e[idx] @ self.chol[k].T
        m = self.model
        m_labels = np.minimum(np.searchsorted(m.weights_cdf_, random.random(n), side="right"),
                              m.n_components_ - 1)
        for k in range(m.n_components_):
            idx = (m_labels == k) & from_model
            new[idx] = m.means_[k] + e[idx] @ m.cholesky_[k].T
        return new

    def __call__(self, coords: FloatArray, random: np.random.RandomState
                 ) -> tuple[FloatArray, FloatArray]:
        new = self.draw(coords.shape[0], random)
        return new, self.log_q(coords) - self.log_q(new)


class _EnvelopeProposal:
    """Independence proposal ``q = p | S`` (the model restricted to the region's envelope).

    On A (inside S) ``p / q`` is constant, so the Metropolis-Hastings ratio is 1 for every
    proposal inside A: the move is rejection sampling inside the chain.
    """

    def __init__(self, problem: Problem) -> None:
        assert problem.envelope is not None
        self.envelope = problem.envelope
        self.model = problem.model

    def __call__(self, coords: FloatArray, random: np.random.RandomState
                 ) -> tuple[FloatArray, FloatArray]:
        new = self.envelope.sample_z(self.model, coords.shape[0], random)
        return new, (self.envelope.log_q(self.model, coords)
                     - self.envelope.log_q(self.model, new))

    def describe(self) -> dict[str, Any]:
        return {"kind": "envelope", "source": self.envelope.source,
                "mass": self.envelope.mass}


@dataclass(frozen=True)
class _ChainRun:
    """One production run of the ensemble: what the thinning and the diagnostics read."""

    sampler: Any  # emcee.EnsembleSampler
    n_walkers: int
    adapt_steps: int  # steps before the proposal's refit (discarded)
    steps: int  # production steps
    tau: FloatArray  # integrated autocorrelation time per dimension
    converged: bool


@dataclass(frozen=True)
class _Thinning:
    """How the production chain became the samples."""

    burn: int
    thin: int
    tau_max: float
    warnings: list[str]


class MCMCSampler(Sampler):
    """emcee ensemble sampler with differential-evolution moves (see the module docstring).

    Moves (per step, by weight): ``DEMove`` ``de_weight``, ``DESnookerMove``
    ``snooker_weight`` and an independence Metropolis-Hastings move ``MHMove`` with a
    Gaussian-mixture proposal fitted to points inside the region
    (``independence_weight``; 0 gives the pure DE mixture). Pure DE moves mix slowly on
    the truncated mixtures of real data (measured on the TNO model, ttc < 3: acceptance
    0.08, tau 45-100 steps), the independence move makes nearly independent proposals
    where the fitted proposal is good, while the DE moves keep exploring where it is not.
    The proposal is fitted to the starting points, refitted once to the chain after
    ``adapt_steps`` steps, and then fixed; everything before the refit is discarded, so the
    production chain is a plain (non-adaptive) Markov chain.

    Parameters
    ----------
    n_walkers : int
        Ensemble size (at least ``2 d + 2``).
    de_weight, snooker_weight, independence_weight : float
        Move probabilities (normalised).
    chunk : int
        Steps between autocorrelation estimates.
    adapt_steps : int
        Steps before the proposal is refitted (0: no refit).
    min_tau_multiple : float
        The production chain must be at least this many (largest) integrated
        autocorrelation times long.
    max_steps : int
        Hard cap on production steps; when reached, ``converged = False`` and a warning.
    """

    name = "mcmc"

    def __init__(self, n_walkers: int = 64, de_weight: float = 0.4,
                 snooker_weight: float = 0.1, independence_weight: float = 0.5,
                 chunk: int = 100, adapt_steps: int = 100, min_tau_multiple: float = 50.0,
                 max_steps: int = 20_000) -> None:
        self.n_walkers = int(n_walkers)
        self.de_weight = float(de_weight)
        self.snooker_weight = float(snooker_weight)
        self.independence_weight = float(independence_weight)
        self.chunk = int(chunk)
        self.adapt_steps = int(adapt_steps)
        self.min_tau_multiple = float(min_tau_multiple)
        self.max_steps = int(max_steps)

    def pilot_plan(self, problem: Problem) -> PilotPlan:
        """A point inside the region per walker (the broadened search finds the rest)."""
        return PilotPlan(need=self.n_walkers)

    def estimate_alone(self, run: Run, pilot: Pilot) -> PRegion:
        """P(A) without samples: a short chain (500 samples) inside the region gives the
        importance sampler its proposal (``PRegionEstimator.estimate``)."""
        drawn = self.draw(run.problem, 500, run.rng, pilot, run.progress)
        return run.estimator.estimate(run.problem, run.rng, mc_draws=pilot.n_draws,
                                      mc_hits=pilot.n_hits, region_z=drawn.z,
                                      bounds=run.bounds)

    @classmethod
    def summarise(cls, diagnostics: dict[str, Any]) -> list[str]:
        d = diagnostics
        return [f"acceptance {d['acceptance_mean']:.2f} (min {d['acceptance_min']:.2f})"
                f", tau {d['tau_max']:.1f}, ESS {d['ess']:.0f} "
                f"(chain {d['ess_chain_min']:.0f}), {d['n_steps']} steps",
                *d.get("warnings", [])]

    def _start(self, problem: Problem, rng: np.random.Generator, pilot: Pilot,
               nw: int) -> tuple[FloatArray, FloatArray]:
        """Distinct starting points inside the region, and the pool they came from."""
        pool = pilot.hits
        if pilot.search_hits.size:
            pool = np.concatenate([pool, pilot.search_hits], axis=0)
        if pool.shape[0] == 0:
            raise EmptyRegionError(
                f"no point inside {problem.region.describe()} to start MCMC from",
                n_draws=pilot.n_draws + pilot.search_draws, n_hits=0,
                p_upper=upper95(0, pilot.n_draws))
        pool = np.unique(pool, axis=0)
        pool = pool[rng.permutation(pool.shape[0])]
        if pool.shape[0] >= nw:
            return pool[:nw], pool
        # too few distinct points: jitter them (small steps in z-space), keep those inside
        start = [pool]
        have = pool.shape[0]
        scale = 0.05
        for _ in range(200):
            base = pool[rng.integers(0, pool.shape[0], size=4 * nw)]
            cand = base + scale * rng.standard_normal(base.shape)
            ok = cand[problem.inside(cand)]
            start.append(ok)
            have += ok.shape[0]
            if have >= nw:
                break
            scale *= 0.7
        allz = np.concatenate(start, axis=0)
        if allz.shape[0] < nw:
            raise EmptyRegionError(
                f"found only {allz.shape[0]} distinct points inside "
                f"{problem.region.describe()} for {nw} walkers: the region is practically "
                "empty or degenerate", n_draws=pilot.n_draws + pilot.search_draws,
                n_hits=pool.shape[0], p_upper=upper95(pilot.n_hits, pilot.n_draws))
        return allz[:nw], allz

    def _moves(self, proposal: MixtureProposal | _EnvelopeProposal | None
               ) -> list[tuple[Any, float]]:
        moves: list[tuple[Any, float]] = [(emcee.moves.DEMove(), self.de_weight),
                                          (emcee.moves.DESnookerMove(), self.snooker_weight)]
        if proposal is not None and self.independence_weight > 0:
            moves.append((emcee.moves.MHMove(proposal), self.independence_weight))
        return [(m, w) for m, w in moves if w > 0]

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        d = problem.ndim
        nw = max(self.n_walkers, 2 * d + 2)
        nw += nw % 2
        p0, pool = self._start(problem, rng, pilot, nw)
        state: Any = np.random.RandomState(int(rng.integers(0, 2**32 - 1))).get_state()
        proposal = self._proposal(problem, rng, pool)
        current = emcee.State(p0, random_state=state)
        adapt = 0
        if isinstance(proposal, MixtureProposal) and self.adapt_steps > 0:
            proposal, current = self._adapt(problem, rng, nw, proposal, current)
            adapt = self.adapt_steps
        sampler = self._sampler(problem, nw, d, proposal, current)
        steps, tau, converged = self._run(sampler, current, n, progress)
        chain = _ChainRun(sampler, nw, adapt, steps, tau, converged)
        z, thinning = self._thinned(chain, n)
        return Draw(z=np.ascontiguousarray(z), method=self.name,
                    diagnostics=self._diagnostics(problem, chain, thinning, n, proposal),
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits)

    def _proposal(self, problem: Problem, rng: np.random.Generator, pool: FloatArray
                  ) -> MixtureProposal | _EnvelopeProposal | None:
        """The independence move's proposal: the region's envelope when it has one, else
        a mixture fitted to the starting pool; None without the move."""
        if self.independence_weight > 0 and problem.envelope is not None:
            return _EnvelopeProposal(problem)
        if self.independence_weight > 0:
            return MixtureProposal(problem.model, pool, int(rng.integers(0, 2**31 - 1)))
        return None

    def _adapt(self, problem: Problem, rng: np.random.Generator, nw: int,
               proposal: MixtureProposal, current: Any) -> tuple[MixtureProposal, Any]:
        """``adapt_steps`` steps with the starting proposal, then the proposal refitted to
        the second half of them: (the refitted proposal, the walkers' state)."""
        sampler = self._sampler(problem, nw, problem.ndim, proposal, current)
        current = sampler.run_mcmc(current, self.adapt_steps)
        chain = sampler.get_chain(discard=self.adapt_steps // 2, flat=True)
        proposal = MixtureProposal(problem.model, np.unique(chain, axis=0),
                                   int(rng.integers(0, 2**31 - 1)))
        return proposal, current

    def _run(self, sampler: emcee.EnsembleSampler, current: Any, n: int,
             progress: ProgressFn | None) -> tuple[int, FloatArray, bool]:
        """The production chain, in chunks until it is ``min_tau_multiple`` tau long with
        ``n`` thinned samples, or ``max_steps``: (steps, tau per dimension, converged)."""
        nw = sampler.nwalkers
        steps = 0
        tau = np.full(sampler.ndim, np.nan)
        while steps < self.max_steps:
            todo = min(self.chunk, self.max_steps - steps)
            current = sampler.run_mcmc(current, todo, skip_initial_state_check=True)
            steps += todo
            tau = integrated_time(sampler.get_chain())
            tau_max = float(np.max(tau)) if np.isfinite(tau).all() else float(steps)
            burn = math.ceil(2 * tau_max)
            thin = max(1, math.ceil(tau_max))
            n_thinned = nw * max(0, (steps - burn) // thin)
            if progress is not None:
                progress("mcmc", min(n_thinned, n), n)
            if steps >= self.min_tau_multiple * tau_max and n_thinned >= n:
                return steps, tau, True
        return steps, tau, False

    def _thinned(self, chain: _ChainRun, n: int) -> tuple[FloatArray, _Thinning]:
        """``n`` samples spread evenly over the post-burn-in, thinned chain (thinning
        dropped, with a warning, when it leaves fewer than ``n``)."""
        steps, tau, sampler = chain.steps, chain.tau, chain.sampler
        tau_max = float(np.max(tau)) if np.isfinite(tau).all() else float(steps)
        burn = min(math.ceil(2 * tau_max), steps - 1)
        thin = max(1, math.ceil(tau_max))
        warnings_: list[str] = []
        flat = sampler.get_chain(discard=burn, thin=thin, flat=True)
        if flat.shape[0] < n:
            warnings_.append(
                f"max_steps={self.max_steps} reached with {flat.shape[0]} thinned samples "
                f"(tau={tau_max:.1f}); thinning reduced to reach n={n}: samples are correlated")
            thin = 1
            flat = sampler.get_chain(discard=burn, flat=True)
            flat = flat[np.linspace(0, flat.shape[0] - 1, n).round().astype(int)]
        elif not chain.converged:
            warnings_.append(f"chain shorter than {self.min_tau_multiple:g} tau "
                             f"({steps} steps, tau={tau_max:.1f}): tau is uncertain")
        # n samples spread evenly over the whole post-burn-in (thinned) chain
        z = flat[np.linspace(0, flat.shape[0] - 1, n).round().astype(int)]
        return z, _Thinning(burn, thin, tau_max, warnings_)

    def _diagnostics(self, problem: Problem, chain: _ChainRun, th: _Thinning, n: int,
                     proposal: MixtureProposal | _EnvelopeProposal | None) -> dict[str, Any]:
        """The draw's diagnostics: the chain's length, autocorrelation, acceptance and
        effective sample sizes, the moves."""
        nw, steps, tau = chain.n_walkers, chain.steps, chain.tau
        acc = np.asarray(chain.sampler.acceptance_fraction, dtype=np.float64)
        ess_per_dim = nw * (steps - th.burn) / np.where(tau > 0, tau, np.inf)
        ess_out = float(min(n, n * th.thin / th.tau_max)) if th.tau_max > 0 else float(n)
        use_ind = self.independence_weight > 0
        return {
            "n_walkers": nw,
            "adapt_steps": chain.adapt_steps,
            "n_steps": steps,
            "burn_in": th.burn,
            "thin": th.thin,
            "tau": [float(t) for t in tau],
            "tau_max": th.tau_max,
            "acceptance_fraction": [float(a) for a in acc],
            "acceptance_mean": float(acc.mean()),
            "acceptance_min": float(acc.min()),
            "ess_chain": [float(e) for e in ess_per_dim],
            "ess_chain_min": float(np.min(ess_per_dim)),
            "ess": ess_out,
            "converged": chain.converged,
            "warnings": th.warnings,
            "n_evaluations": problem.n_evals,
            "moves": {"DEMove": self.de_weight, "DESnookerMove": self.snooker_weight,
                      "independence": self.independence_weight if use_ind else 0.0},
            "independence_proposal": (None if proposal is None else
                                      proposal.describe()),
        }

    def _sampler(self, problem: Problem, nw: int, d: int,
                 proposal: MixtureProposal | _EnvelopeProposal | None,
                 current: Any) -> emcee.EnsembleSampler:
        sampler = emcee.EnsembleSampler(nw, d, problem.log_prob, moves=self._moves(proposal),
                                        vectorize=True)
        sampler.random_state = current.random_state
        now: Any = sampler.random_state
        if not np.array_equal(now[1], current.random_state[1]):  # the setter fails silently
            raise SamplerError("could not seed emcee's random state")
        return sampler


def integrated_time(chain: FloatArray, c: float = 5.0) -> FloatArray:
    """Integrated autocorrelation time per dimension, chain of shape (steps, walkers, d).

    emcee's estimator (``emcee.autocorr``: normalised autocorrelation per walker, averaged
    over walkers, Sokal's automatic window with ``c = 5``), except that walkers which did
    not move in a dimension (zero variance: emcee would divide by zero) are left out; if
    none moved, tau is the chain length (nothing is known).
    """
    n_t, _, n_d = chain.shape
    tau = np.full(n_d, float(n_t))
    for d in range(n_d):
        f = np.zeros(n_t)
        used = 0
        for k in range(chain.shape[1]):
            x = chain[:, k, d]
            if not np.ptp(x) > 1e-12 * (1.0 + abs(float(x[0]))):
                continue
            with np.errstate(invalid="ignore", divide="ignore"):
                acf = emcee.autocorr.function_1d(x)
            if np.isfinite(acf).all():
                f += acf
                used += 1
        if used:
            f /= used
            taus = 2.0 * np.cumsum(f) - 1.0
            tau[d] = max(1.0, float(taus[emcee.autocorr.auto_window(taus, c)]))
    return tau

