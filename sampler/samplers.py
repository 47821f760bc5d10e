"""Samplers of the truncated model: strategy objects with one method, ``draw``.

The target is the model density restricted to a region A (constraints and physical bounds)
and renormalised: ``p(x | A) = p(x) 1_A(x) / P(A)``. ``Problem`` binds a model and a region
and draws from the *proposal*: the model restricted to the region's half-space envelope
(``sampler.envelope``) when there is one, else the whole model.

* ``RejectionSampler`` — exact: draw i.i.d. from the proposal (a numpy Generator that is
  advanced, labels then Gaussians), keep the draws inside A. Every kept draw is an
  independent sample (effective sample size = n).
* ``MCMCSampler`` — emcee ``EnsembleSampler`` in the model's standardised z-space with a
  vectorised log-probability (``log p_z(z)``, -inf outside A); moves ``DEMove`` 0.4,
  ``DESnookerMove`` 0.1 and an independence ``MHMove`` 0.5 (proposal: the envelope, or a
  defensive Gaussian-mixture fit); walkers started at distinct points inside A (exact draws
  found by the pilot, or by the broadened search); it runs in chunks until the chain is at
  least ``min_tau_multiple`` integrated autocorrelation times long and holds ``n`` thinned
  post-burn-in samples (burn-in ``ceil(2 tau)``, thinning ``ceil(tau)``), or until
  ``max_steps``. Diagnostics: acceptance fraction per walker, tau per feature, effective
  sample size. emcee draws from its own ``RandomState``, seeded from our Generator through
  its ``random_state`` property (emcee 3.1 has no seed argument), so the same seed gives the
  same chain.
* ``AutoSampler`` — rejection when its expected cost ``n / p_pilot`` draws is below the
  MCMC cost model ``cost_ratio * (n * tau_guess + n_walkers * burn_guess)`` (a fixed,
  documented rule, so the choice is deterministic), MCMC otherwise.
"""
from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import emcee
import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from sampler._exceptions import EmptyRegionError, SamplerError
from sampler.constraints import Region
from sampler.envelope import HalfSpace, find_envelope
from sampler.model import CutInGMM

__all__ = [
    "SAMPLERS",
    "AutoSampler",
    "Draw",
    "MCMCSampler",
    "Problem",
    "ProgressFn",
    "RejectionSampler",
    "Sampler",
    "make_sampler",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: progress callback: (stage, done, total)
ProgressFn = Callable[[str, int, int], None]


class Problem:
    """A fitted model and a region: membership and log-probability in the model's z-space.

    With ``use_envelope`` (default), the tightest half-space envelope S of the region
    (``sampler.envelope``) is found; then ``draw_z`` draws exactly from the model
    restricted to S instead of the whole model (same target after rejection, fewer misses).
    """

    def __init__(self, model: CutInGMM, region: Region, use_envelope: bool = True) -> None:
        model._check_fitted()
        self.model = model
        self.region = region
        self.n_evals = 0
        self.envelope: HalfSpace | None = find_envelope(model, region) if use_envelope else None

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
    """

    z: FloatArray
    method: str
    diagnostics: dict[str, Any] = field(default_factory=dict)
    mc_draws: int = 0
    mc_hits: int = 0


@dataclass
class Pilot:
    """Plain Monte-Carlo draws made before sampling (exact draws; reused by the samplers)."""

    n_draws: int
    hits: FloatArray  # (k, d) z-space, inside the region, in draw order
    search_hits: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    search_draws: int = 0

    @property
    def n_hits(self) -> int:
        return int(self.hits.shape[0])

    @property
    def p_hat(self) -> float:
        return self.n_hits / self.n_draws if self.n_draws else 0.0


class Sampler(ABC):
    """Strategy: draw ``n`` samples of the truncated model given the pilot's draws."""

    name: str = "abstract"

    @abstractmethod
    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        """Return ``n`` samples inside the region (advancing ``rng``)."""

    def settings(self) -> dict[str, Any]:
        """JSON-able settings, stored with the sample set."""
        return {"name": self.name, **{k: v for k, v in vars(self).items()
                                      if not k.startswith("_")}}


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
                    p_upper=problem.proposal_mass * _upper95(hits, draws))
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


def _upper95(k: int, n: int) -> float:
    """One-sided 95 % upper bound of a binomial proportion (exact)."""
    from scipy import stats

    if n <= 0:
        return 1.0
    if k >= n:
        return 1.0
    return float(stats.beta.ppf(0.95, k + 1, n - k))


class _MixtureProposal:
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
        m_labels = np.minimum(np.searchsorted(m._cdf, random.random(n), side="right"),
                              m.n_components_ - 1)
        for k in range(m.n_components_):
            idx = (m_labels == k) & from_model
            new[idx] = m.means_[k] + e[idx] @ m._chol[k].T
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
                p_upper=_upper95(0, pilot.n_draws))
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
                n_hits=pool.shape[0], p_upper=_upper95(pilot.n_hits, pilot.n_draws))
        return allz[:nw], allz

    def _moves(self, proposal: _MixtureProposal | _EnvelopeProposal | None
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
        use_ind = self.independence_weight > 0
        proposal: _MixtureProposal | _EnvelopeProposal | None = None
        if use_ind and problem.envelope is not None:
            proposal = _EnvelopeProposal(problem)
        elif use_ind:
            proposal = _MixtureProposal(problem.model, pool, int(rng.integers(0, 2**31 - 1)))
        current = emcee.State(p0, random_state=state)
        adapt = 0
        if isinstance(proposal, _MixtureProposal) and self.adapt_steps > 0:
            sampler = self._sampler(problem, nw, d, proposal, current)
            current = sampler.run_mcmc(current, self.adapt_steps)
            adapt = self.adapt_steps
            chain = sampler.get_chain(discard=self.adapt_steps // 2, flat=True)
            proposal = _MixtureProposal(problem.model, np.unique(chain, axis=0),
                                        int(rng.integers(0, 2**31 - 1)))
        sampler = self._sampler(problem, nw, d, proposal, current)
        steps = 0
        tau = np.full(d, np.nan)
        converged = False
        while steps < self.max_steps:
            todo = min(self.chunk, self.max_steps - steps)
            current = sampler.run_mcmc(current, todo, skip_initial_state_check=True)
            steps += todo
            tau = _tau(sampler.get_chain())
            tau_max = float(np.max(tau)) if np.isfinite(tau).all() else float(steps)
            burn = math.ceil(2 * tau_max)
            thin = max(1, math.ceil(tau_max))
            n_thinned = nw * max(0, (steps - burn) // thin)
            if progress is not None:
                progress("mcmc", min(n_thinned, n), n)
            if steps >= self.min_tau_multiple * tau_max and n_thinned >= n:
                converged = True
                break
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
        elif not converged:
            warnings_.append(f"chain shorter than {self.min_tau_multiple:g} tau "
                             f"({steps} steps, tau={tau_max:.1f}): tau is uncertain")
        # n samples spread evenly over the whole post-burn-in (thinned) chain
        z = flat[np.linspace(0, flat.shape[0] - 1, n).round().astype(int)]
        acc = np.asarray(sampler.acceptance_fraction, dtype=np.float64)
        ess_per_dim = nw * (steps - burn) / np.where(tau > 0, tau, np.inf)
        ess_out = float(min(n, n * thin / tau_max)) if tau_max > 0 else float(n)
        diag = {
            "n_walkers": nw,
            "adapt_steps": adapt,
            "n_steps": steps,
            "burn_in": burn,
            "thin": thin,
            "tau": [float(t) for t in tau],
            "tau_max": tau_max,
            "acceptance_fraction": [float(a) for a in acc],
            "acceptance_mean": float(acc.mean()),
            "acceptance_min": float(acc.min()),
            "ess_chain": [float(e) for e in ess_per_dim],
            "ess_chain_min": float(np.min(ess_per_dim)),
            "ess": ess_out,
            "converged": converged,
            "warnings": warnings_,
            "n_evaluations": problem.n_evals,
            "moves": {"DEMove": self.de_weight, "DESnookerMove": self.snooker_weight,
                      "independence": self.independence_weight if use_ind else 0.0},
            "independence_proposal": (None if proposal is None else
                                      proposal.describe()),
        }
        return Draw(z=np.ascontiguousarray(z), method=self.name, diagnostics=diag,
                    mc_draws=pilot.n_draws, mc_hits=pilot.n_hits)

    def _sampler(self, problem: Problem, nw: int, d: int,
                 proposal: _MixtureProposal | _EnvelopeProposal | None,
                 current: Any) -> emcee.EnsembleSampler:
        sampler = emcee.EnsembleSampler(nw, d, problem.log_prob, moves=self._moves(proposal),
                                        vectorize=True)
        sampler.random_state = current.random_state
        now: Any = sampler.random_state
        if not np.array_equal(now[1], current.random_state[1]):  # the setter fails silently
            raise SamplerError("could not seed emcee's random state")
        return sampler


def _tau(chain: FloatArray, c: float = 5.0) -> FloatArray:
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
    """

    name = "auto"

    def __init__(self, rejection: RejectionSampler | None = None,
                 mcmc: MCMCSampler | None = None, cost_ratio: float = 50.0,
                 tau_guess: float = 30.0, burn_guess: float = 600.0) -> None:
        self.rejection = rejection or RejectionSampler()
        self.mcmc = mcmc or MCMCSampler()
        self.cost_ratio = float(cost_ratio)
        self.tau_guess = float(tau_guess)
        self.burn_guess = float(burn_guess)

    def choose(self, n: int, pilot: Pilot) -> Sampler:
        if pilot.n_hits == 0:
            return self.mcmc
        rej_cost = n / pilot.p_hat
        mcmc_cost = self.cost_ratio * (n * self.tau_guess
                                       + self.mcmc.n_walkers * self.burn_guess)
        if rej_cost <= mcmc_cost and rej_cost <= self.rejection.max_draws:
            return self.rejection
        return self.mcmc

    def draw(self, problem: Problem, n: int, rng: np.random.Generator, pilot: Pilot,
             progress: ProgressFn | None = None) -> Draw:
        chosen = self.choose(n, pilot)
        out = chosen.draw(problem, n, rng, pilot, progress)
        out.diagnostics["auto"] = {"p_pilot": pilot.p_hat, "chosen": chosen.name,
                                   "cost_ratio": self.cost_ratio,
                                   "tau_guess": self.tau_guess, "burn_guess": self.burn_guess}
        return out

    def settings(self) -> dict[str, Any]:
        return {"name": self.name, "cost_ratio": self.cost_ratio, "tau_guess": self.tau_guess,
                "burn_guess": self.burn_guess, "rejection": self.rejection.settings(),
                "mcmc": self.mcmc.settings()}


SAMPLERS: dict[str, type[Sampler]] = {"auto": AutoSampler, "rejection": RejectionSampler,
                                      "mcmc": MCMCSampler}


def make_sampler(method: str | Sampler) -> Sampler:
    """A Sampler from its name (``auto``, ``rejection``, ``mcmc``) or pass one through."""
    if isinstance(method, Sampler):
        return method
    if method not in SAMPLERS:
        raise SamplerError(f"sampler: unknown method {method!r}; valid: {', '.join(SAMPLERS)}")
    return SAMPLERS[method]()
