"""Importance-sampling pieces of ``subset-is`` (``sampler.methods.rare``): the defensive kernel
density, a stage of importance draws with its estimate, and independence
Metropolis-Hastings chains over those draws.
"""
from __future__ import annotations

import math
import time
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.special import gammaln, logsumexp

from sampler.errors import EmptyRegionError, SamplerError
from sampler.methods.problem import FloatArray
from sampler.methods.subset import LimitState

__all__ = ["ImportanceStage", "KernelMixture", "KernelProposal", "Proposal", "ZDensity",
           "independence_chain", "kish_ess"]


class ZDensity(Protocol):
    """The base law of an importance stage: the model (``CutInGMM``) or one of its strata
    (``sampler.methods.strata.Stratum``)."""

    @property
    def n_features(self) -> int: ...

    def log_density_z(self, z: FloatArray) -> FloatArray: ...

    def sample_z(self, n: int, rng: np.random.Generator) -> FloatArray: ...


class Proposal(Protocol):
    """An importance density in z-space: ``KernelProposal`` or ``KernelMixture``."""

    alpha: float
    k: int

    def log_q(self, z: FloatArray) -> FloatArray: ...

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray: ...


class _Defensive:
    """``q = (1 - alpha) g + alpha p`` given ``g`` (``log_g``, ``draw_g``) and ``p``."""

    model: ZDensity
    alpha: float

    def log_g(self, z: FloatArray) -> FloatArray:
        raise NotImplementedError

    def draw_g(self, n: int, rng: np.random.Generator) -> FloatArray:
        raise NotImplementedError

    def log_q(self, z: FloatArray) -> FloatArray:
        return np.asarray(np.logaddexp(math.log(self.alpha) + self.model.log_density_z(z),
                                       math.log1p(-self.alpha) + self.log_g(z)),
                          dtype=np.float64)

    def draw(self, n: int, rng: np.random.Generator) -> FloatArray:
        from_model = rng.random(n) < self.alpha
        out = self.draw_g(n, rng)
        n_m = int(from_model.sum())
        if n_m:
            out[from_model] = self.model.sample_z(n_m, rng)
        return np.asarray(out, dtype=np.float64)


class KernelProposal(_Defensive):
    """Defensive kernel density ``q = (1 - alpha) g + alpha p`` in the model's z-space.

    ``g`` is an equal mixture of multivariate Student-t kernels (``nu`` degrees of freedom:
    heavier tails than Gaussians, so a region's tail that the centres under-represent
    still gets draws; Oh & Berger 1992, JASA 87, mixtures of t as importance densities)
    centred at ``centres`` (m, d; a repeated centre counts as often as it appears), all with
    the scale matrix ``h^2 S``: ``S`` the covariance of ``shape`` (default the centres),
    ``h`` Silverman's factor ``(4 / (d + 2))^(1 / (d + 4)) n^(-1 / (d + 4))`` times
    ``inflate``, ``n = n_bandwidth`` (default m; the distinct centres when they repeat).
    ``p`` is the model (weights ``p / q <= 1 / alpha``).
    """

    def __init__(self, model: ZDensity, centres: FloatArray, inflate: float, alpha: float,
                 nu: float, shape: FloatArray | None = None,
                 n_bandwidth: int | None = None) -> None:
        m, d = centres.shape
        ref = centres if shape is None else shape
        cov = np.cov(ref, rowvar=False) + 1e-9 * np.eye(d)
        nb = m if n_bandwidth is None else int(n_bandwidth)
        h = (4.0 / (d + 2)) ** (1.0 / (d + 4)) * nb ** (-1.0 / (d + 4)) * inflate
        self.model = model
        self.alpha = float(alpha)
        self.nu = float(nu)
        self.k = m
        self.centres = np.asarray(centres, dtype=np.float64)
        self.chol = np.linalg.cholesky(cov * h * h)
        self._inv_t = np.linalg.inv(self.chol).T  # z @ _inv_t whitens
        self._wc = self.centres @ self._inv_t
        self._wc2 = np.einsum("ij,ij->i", self._wc, self._wc)
        self._log_norm = (gammaln(0.5 * (nu + d)) - gammaln(0.5 * nu)
                          - 0.5 * d * math.log(nu * math.pi)
                          - float(np.log(np.diag(self.chol)).sum()) - math.log(m))

    def log_g(self, z: FloatArray) -> FloatArray:
        wz = z @ self._inv_t
        d2 = np.einsum("ij,ij->i", wz, wz)[:, None] + self._wc2[None, :] - 2.0 * wz @ self._wc.T
        d2 = np.maximum(d2, 0.0)
        d = z.shape[1]
        return np.asarray(self._log_norm + logsumexp(
            -0.5 * (self.nu + d) * np.log1p(d2 / self.nu), axis=1), dtype=np.float64)

    def draw_g(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` draws of the kernel mixture ``g`` alone."""
        d = self.centres.shape[1]
        idx = rng.integers(0, self.k, size=n)
        e = rng.standard_normal((n, d)) @ self.chol.T
        scale = np.sqrt(self.nu / rng.chisquare(self.nu, size=n))
        return np.asarray(self.centres[idx] + e * scale[:, None], dtype=np.float64)


class KernelMixture(_Defensive):
    """``q = (1 - alpha) sum_j s_j g_j + alpha p``: several kernel densities ``g_j`` (the
    kernel mixtures of ``KernelProposal`` objects, each with its own centres and bandwidth;
    their own ``alpha`` is not used) in fixed shares ``s_j`` (normalised) beside the model
    ``p`` with share ``alpha`` (weights ``p / q <= 1 / alpha`` as there)."""

    def __init__(self, model: ZDensity, parts: list[KernelProposal], shares: list[float],
                 alpha: float) -> None:
        s = np.asarray(shares, dtype=np.float64)
        self.model = model
        self.parts = parts
        self.shares = s / s.sum()
        self.alpha = float(alpha)
        self.k = sum(p.k for p in parts)
        self.centres = np.concatenate([p.centres for p in parts], axis=0)

    def log_g(self, z: FloatArray) -> FloatArray:
        return np.asarray(logsumexp(np.stack([math.log(s) + p.log_g(z) for p, s
                                              in zip(self.parts, self.shares, strict=True)]),
                                    axis=0), dtype=np.float64)

    def draw_g(self, n: int, rng: np.random.Generator) -> FloatArray:
        part = rng.choice(len(self.parts), size=n, p=self.shares)
        out = np.empty((n, self.centres.shape[1]))
        for j, p in enumerate(self.parts):
            sel = part == j
            if sel.any():
                out[sel] = p.draw_g(int(sel.sum()), rng)
        return out


class ImportanceStage:
    """Draws of the defensive proposal q with their limit state: P(A) and its CoV so far."""

    def __init__(self, model: ZDensity, limit_state: LimitState, proposal: Proposal,
                 deadline: float, max_seconds: float) -> None:
        self.model = model
        self.limit_state = limit_state
        self.proposal = proposal
        self.deadline = deadline
        self.max_seconds = max_seconds
        self.n = 0
        self._z: list[FloatArray] = []
        self._lw: list[FloatArray] = []  # log p - log q, -inf outside A

    def add(self, n: int, rng: np.random.Generator, batch: int = 4096) -> None:
        """Draw ``n`` more points of q (in batches, the time budget checked between)."""
        done = 0
        while done < n:
            if time.monotonic() > self.deadline:
                raise SamplerError(
                    f"subset-is: stopped after max_seconds={self.max_seconds:g} s in the "
                    f"importance stage ({self.n} draws of q); raise max_seconds")
            b = min(batch, n - done)
            z = self.proposal.draw(b, rng)
            g = np.asarray(self.limit_state(z), dtype=np.float64)
            lw = self.model.log_density_z(z) - self.proposal.log_q(z)
            self._z.append(z)
            self._lw.append(np.where(g <= 0.0, lw, -np.inf))
            self.n += b
            done += b

    @property
    def z(self) -> FloatArray:
        return np.concatenate(self._z, axis=0)

    @property
    def log_w(self) -> FloatArray:
        return np.concatenate(self._lw)

    def estimate(self) -> tuple[float, float]:
        """(P(A), CoV): mean of the weights (0 outside A), standard error / mean."""
        w = np.exp(self.log_w)
        p = float(w.mean())
        if not p > 0:
            return 0.0, math.inf
        return p, float(w.std(ddof=1) / math.sqrt(w.size) / p)


def kish_ess(log_w: FloatArray) -> float:
    """Kish's effective sample size of weights given as logs."""
    w = np.exp(log_w - log_w.max())
    return float(w.sum() ** 2 / (w * w).sum())


def independence_chain(log_w: FloatArray, rng: np.random.Generator, n_chains: int = 4
                       ) -> tuple[NDArray[np.int64], FloatArray]:
    """Independence Metropolis-Hastings over a stream of proposals with log-weights.

    ``log_w[i]`` is ``log p - log q`` of proposal i (-inf outside A). The stream is split
    round-robin over ``n_chains`` chains; each starts at a proposal inside A chosen with
    probability proportional to its weight (importance resampling: close to the target,
    so the burn-in is short) and moves to proposal i with probability
    ``min(1, w_i / w_state)``. Returns (indices of the states, shape (steps, n_chains);
    acceptance per chain).
    """
    inside = np.flatnonzero(np.isfinite(log_w))
    if inside.size == 0:
        raise EmptyRegionError("independence chain: no proposal inside the region")
    w = np.exp(log_w[inside] - log_w[inside].max())
    starts = inside[rng.choice(inside.size, size=n_chains, p=w / w.sum())]
    steps = log_w.size // n_chains
    log_u = np.log(rng.random((steps, n_chains)))
    states = np.empty((steps, n_chains), dtype=np.int64)
    accepted = np.zeros(n_chains)
    for c in range(n_chains):
        s = int(starts[c])
        ls = float(log_w[s])
        prop = log_w[c::n_chains][:steps]
        idx = np.arange(c, c + n_chains * steps, n_chains)
        lu = log_u[:, c]
        for t in range(steps):  # scalar loop: cheap next to the limit state
            if lu[t] < prop[t] - ls:
                s = int(idx[t])
                ls = float(prop[t])
                accepted[c] += 1
            states[t, c] = s
    return states, accepted / max(steps, 1)

