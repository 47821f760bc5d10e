"""The region's probability mass P(A) under the model, with a confidence interval.

Definition. The mixture puts a little mass on vectors no car can drive (outside the physical
bounds B, see ``sampler.region.constraints.PHYSICAL_BOUNDS``). P(A) is the mass of the region
*among physical cut-ins*: ``P(A) = P(A and B) / P(B)`` under the model (every region A
with bounds on lies inside B). ``P(B)`` is estimated once per sample set from ``n_bounds``
plain draws; the interval of P(A) combines both intervals conservatively:
``[lo(A and B) / hi(B), hi(A and B) / lo(B)]``.

Estimators of ``P(A and B)``:

* ``mc`` — plain Monte Carlo: ``k`` of ``N`` model draws inside; exact Clopper-Pearson
  interval. Used whenever at least ``mc_min_hits`` draws hit the region (so the relative
  error stays below about 20 %).
* ``envelope`` — the same with draws from the model restricted to a half-space envelope
  S of the region (``sampler.methods.envelope``): ``P(A and B) = P(S) k / N``, P(S) exact, the
  interval ``P(S)`` times the Clopper-Pearson interval of ``k / N``. Accurate for rare
  regions when S is tight (ttc < 1 on the TNO model: P(A) ~ 1e-6, P(A | S) ~ 0.05).
* ``subset`` — subset simulation (``sampler.methods.subset``) when the sampler was ``subset``:
  its estimate, a log-normal interval from its conservative CoV bound.
* ``subset-is`` — subset levels then importance sampling (``sampler.methods.rare``) when that
  sampler made the samples (``auto`` for rare regions): its estimate, a log-normal
  interval from its CoV (sample standard error).
* ``is`` — importance sampling with a defensive mixture (Hesterberg 1995) for rare regions
  (in practice P(A) < 1e-4, where the pilot's ~1e6 draws hit fewer than 100 times):
  proposal ``q = alpha p + (1 - alpha) g`` in z-space, ``g`` a Gaussian mixture (K <= 3 by
  BIC) fitted to samples inside the region with covariances inflated by ``inflate**2``;
  estimate
  ``mean(w 1_A)`` with ``w = p / q <= 1 / alpha`` (bounded weights: finite variance even
  where ``g`` is too narrow), normal interval from the sample standard deviation.

Exposure weight of sample i (``exposure_weights``): ``P(A) / n`` for every sample of a set
drawn from ``p(x | A)`` (rejection and MCMC both target it). It is the share of all
physical real-world cut-ins (as the model sees them) that sample i stands for: the weights
sum to P(A), and ``sum_i w_i 1[sample i fails]`` = failure share x P(A) estimates the
probability that a real cut-in is in A *and* makes the system fail; multiplied by a cut-in
rate per hour or km it is a real-world failure rate.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from sampler.errors import EmptyRegionError
from sampler.intervals import clopper_pearson, upper_bound
from sampler.methods.mcmc import MixtureProposal
from sampler.methods.problem import Pilot, Problem, ProgressFn
from sampler.model.memo import MODEL_SEED, memoised
from sampler.region.constraints import Region, implied_bounds

__all__ = ["PRegion", "PRegionEstimator"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PRegion:
    """P(A) with its interval. Probabilities are in [0, 1]."""

    estimate: float
    ci_low: float
    ci_high: float
    confidence: float
    method: str  # "mc", "envelope", "is", "subset", "subset-is" or "split" (a sum of parts)
    n_draws: int  # draws behind the estimate (model draws for mc, proposal draws for is)
    n_hits: int  # of those, inside the region
    p_bounds: float  # P(B), the model's mass inside the physical bounds
    p_bounds_ci: tuple[float, float]
    p_joint: float  # P(A and B)
    cov: float | None = None  # coefficient of variation of the estimate, when known

    @property
    def rel_halfwidth(self) -> float:
        """Half the interval's width relative to the estimate (inf when the estimate is 0)."""
        if self.estimate <= 0:
            return math.inf
        return 0.5 * (self.ci_high - self.ci_low) / self.estimate

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["p_bounds_ci"] = list(self.p_bounds_ci)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PRegion:
        d = dict(d)
        d["p_bounds_ci"] = tuple(d["p_bounds_ci"])
        d.setdefault("cov", None)
        return cls(**d)

    def __str__(self) -> str:
        return (f"P(A)={self.estimate:.3g} [{self.ci_low:.3g}, {self.ci_high:.3g}] "
                f"({self.method}, {self.confidence:.0%}, {self.n_hits}/{self.n_draws})")


#: hits of the extended pilot's probe, which only sizes its plain Monte Carlo run
PROBE_HITS = 20


def _kinematic_part(region: Region) -> Region:
    """The region without its criticality constraints, with the ``btn_bound`` limits they
    imply (what costs no simulation: ``sampler.region.constraints.implied_bounds``)."""
    kept = tuple(c for c in region.constraints if c.tier < 2)
    kin = Region(constraints=kept + implied_bounds(region.constraints),
                 lane_width=region.lane_width, physical_bounds=region.physical_bounds)
    return kin if region._model is None else kin.bind(region._model)


def _draw_inside(problem: Problem, kin: Region | None, n: int, rng: np.random.Generator
                 ) -> tuple[FloatArray, int]:
    """``n`` draws of the problem's proposal: (those inside the region, the rows that were
    simulated: inside ``kin``, the region's part that costs nothing; 0 without ``kin``)."""
    z = problem.draw_z(n, rng)
    if kin is None:
        return z[problem.inside(z)], 0
    x = problem.params(z)
    idx = np.flatnonzero(kin.contains(x))
    inside = np.zeros(n, dtype=bool)
    if idx.size:
        inside[idx] = problem.region.contains(x[idx])
    problem.n_evals += n
    return z[inside], int(idx.size)


def _add_batch(problem: Problem, kin: Region | None, n: int, rng: np.random.Generator,
               hits: list[FloatArray], counts: tuple[int, int, int]) -> tuple[int, int, int]:
    """``n`` more draws (``_draw_inside``): their hits appended to ``hits``; returns the
    running (hits, draws, simulated rows) given the previous ``counts``."""
    inside, sims = _draw_inside(problem, kin, n, rng)
    hits.append(inside)
    return counts[0] + inside.shape[0], counts[1] + n, counts[2] + sims


@dataclass(eq=False)
class PRegionEstimator:
    """Pilot draws, the broadened search for rare regions, and the P(A) estimators.

    Parameters
    ----------
    pilot_hits : int
        Stop the plain-MC pilot once this many draws fell inside the region ...
    pilot_max : int
        ... or after this many draws.
    pilot_max_costly : int
        The same cap when the region has a criticality constraint (closed-loop
        simulations, ~1e4-1e5 rows/s): a rare such region goes to subset-is instead of
        spending 10^6 simulations on the pilot.
    mc_min_hits : int
        Fewer plain-MC hits than this switch P(A) to importance sampling.
    n_is : int
        Proposal draws of the importance sampler.
    defensive : float
        alpha, the model's share of the defensive mixture.
    inflate : float
        Scale of the fitted Gaussian's standard deviations.
    n_bounds : int
        Plain draws for P(B).
    search_scales : tuple of float
        Widening factors tried (in order) when the pilot found fewer than ``search_need``
        points inside the region.
    search_draws : int
        Draws per widening factor.
    min_p : float
        A region whose P(A) upper bound is below this is "practically empty" (error).
    confidence : float
    exact_sims : int
        Simulations plain MC may spend on a criticality region (``sample`` with ``auto``,
        ``estimate_p_region``) before the rare-event methods take over: the pilot goes on
        while ``mc_min_hits`` hits look reachable within it (``extend_pilot``; 200,000
        rows, about 4 s; 0: off).
    thin_share, exact_sims_thin : float, int
        When fewer than ``thin_share`` of the pilot's draws fall inside the region's
        kinematic part (a thin band: 2.9 < ttc < 3 fills 5.8 % of its ``ttc<3`` envelope,
        ``ttc<3`` itself 38 %), the budget is ``exact_sims_thin`` (2,000,000 rows, about
        40 s): subset-is was measured unreliable there (docs/sampler.md).
    exact_draws : int
        Model draws the extended pilot may make (its probe and plain run together; 2^25,
        at most about 100 s at ~3 us per draw). With a ``btn``/``a_req`` lower limit nearly every
        draw is ruled out by ``btn_bound`` without a simulation, so it is the draws, not
        the simulations, that bound such a run.
    """

    pilot_hits: int = 400
    pilot_max: int = 1 << 20
    pilot_max_costly: int = 1 << 13
    mc_min_hits: int = 100
    n_is: int = 1 << 15
    defensive: float = 0.1
    inflate: float = 1.5
    n_bounds: int = 1 << 15
    search_scales: tuple[float, ...] = (1.5, 2.0, 3.0)
    search_draws: int = 1 << 18
    min_p: float = 1e-12
    confidence: float = 0.95
    exact_sims: int = 200_000
    thin_share: float = 0.1
    exact_sims_thin: int = 2_000_000
    exact_draws: int = 1 << 25

    def __post_init__(self) -> None:
        """Each setting as its declared type (numpy scalars, an int for a float: the
        ``settings()`` record stays plain JSON)."""
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("int", int):
                value = int(value)
            elif f.type in ("float", float):
                value = float(value)
            else:  # search_scales
                value = tuple(float(s) for s in value)
            setattr(self, f.name, value)

    def settings(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self).items()}

    # ---------------------------------------------------------------- P(B)

    def p_bounds(self, problem: Problem, rng: np.random.Generator) -> tuple[float, float, float]:
        """P(B) and its interval from ``n_bounds`` plain draws.

        P(B) is a property of the model (and the region's lane width): it is estimated once
        per model object from draws of a generator seeded with ``sampler.model.memo.MODEL_SEED``
        and then reused (``sampler.model.memo``). ``rng`` still advances by ``n_bounds`` draws, so
        the samples of a seed are the same whether or not P(B) was memoised.
        """
        problem.model.sample_z(self.n_bounds, rng)  # keep the caller's stream as it was
        region = problem.region
        key = ("p_bounds", region.lane_width, region.physical_bounds, self.n_bounds)
        k = memoised(problem.model, key, lambda: int(problem.in_bounds(
            problem.model.sample_z(self.n_bounds, np.random.default_rng(MODEL_SEED))).sum()))
        if k == 0:
            raise EmptyRegionError(
                f"none of {self.n_bounds} model draws satisfies the physical bounds: the "
                "model does not describe physical cut-ins (check the fit report)",
                n_draws=self.n_bounds, n_hits=0)
        lo, hi = clopper_pearson(k, self.n_bounds, self.confidence)
        return k / self.n_bounds, lo, hi

    # ---------------------------------------------------------------- pilot and search

    def pilot(self, problem: Problem, rng: np.random.Generator, need: int,
              progress: ProgressFn | None = None, extend: bool = False) -> Pilot:
        """Plain MC in growing batches until ``pilot_hits`` hits or ``pilot_max`` draws;
        with ``extend``, a criticality region's pilot goes on while plain MC can still
        reach ``mc_min_hits`` within ``exact_sims`` simulations (``extend_pilot``); then,
        if fewer than ``need`` hits, the broadened search."""
        hits: list[FloatArray] = []
        n_hits = n_draws = n_sim = 0
        batch = 1 << 14
        costly = any(c.tier == 2 for c in problem.region.constraints)  # closed-loop runs
        cap = self.pilot_max_costly if costly else self.pilot_max
        kin = _kinematic_part(problem.region) if costly else None
        while n_hits < self.pilot_hits and n_draws < cap:
            b = min(batch, cap - n_draws)
            n_hits, n_draws, n_sim = _add_batch(problem, kin, b, rng, hits,
                                                (n_hits, n_draws, n_sim))
            batch = min(batch * 2, 1 << 18)
            if progress is not None:
                progress("pilot", n_draws, cap)
        pilot = Pilot(n_draws=n_draws, hits=np.concatenate(hits, axis=0), n_simulated=n_sim)
        if extend and kin is not None:
            self.extend_pilot(problem, kin, rng, pilot, progress)
        if pilot.n_hits < need:
            self.search(problem, rng, pilot, need)
        return pilot

    def extend_pilot(self, problem: Problem, kin: Region, rng: np.random.Generator,
                     pilot: Pilot, progress: ProgressFn | None = None) -> None:
        """More plain draws for a criticality region while plain MC can still reach
        ``mc_min_hits`` hits within ``exact_sims`` simulations (``kin``: the region
        without its criticality constraints).

        Plain MC simulates only the draws inside the bounds and the kinematic constraints
        (checked first, for free; for a lower limit on ``btn`` or ``a_req`` also the
        ``btn_bound`` it implies, which rules out nearly every draw that does not reach it:
        ``sampler.region.btn_bound``), and its estimate is exact. A region that is rare only
        through its kinematic part (a thin band such as ``2.9 < ttc < 3``) but not given
        it is then estimated exactly: subset-is's chains barely move in such a band, and
        its estimate there was measured 0.35-0.85 of the brute force on average, with
        intervals that missed it (docs/sampler.md).

        Two steps. A probe goes on in doubling batches until ``PROBE_HITS`` hits, unless
        the budget looks out of reach (``mc_min_hits`` hits at the one-sided 95 % upper
        bound of the hit rate per simulation would exceed it). If the probe's rate puts
        ``mc_min_hits`` hits within the budget, a plain run of fresh draws, its size fixed
        from that rate, replaces the pilot (``pilot.plain``; the probe is counted in
        ``probe_draws`` and ``n_simulated``): its estimate is binomial, unbiased and has
        an exact interval, whereas one over draws that were continued or stopped on their
        own hits is not. Otherwise the pilot keeps the probe's draws and the caller goes
        on to the rare-event methods. The budget is ``exact_sims_thin`` instead when the
        kinematic part is thin (fewer than ``thin_share`` of the pilot's draws inside
        it). The draws, cheap but not free (a few microseconds each with the bound), are
        capped at ``exact_draws`` (the probe and the plain run together)."""
        n_hits, n_draws, n_sim = pilot.n_hits, pilot.n_draws, pilot.n_simulated
        budget = self.exact_sims
        if n_draws and n_sim < self.thin_share * n_draws:
            # a thin kinematic part (a ttc band): subset-is's chains are unreliable there
            budget = max(budget, self.exact_sims_thin)
        if budget <= 0:
            return
        hits = [pilot.hits]
        batch = max(n_draws, 1 << 12)
        # 1. the probe: until PROBE_HITS hits show the rate (or the budget looks out of
        #    reach, judged on the one-sided 95 % upper bound of the rate)
        while n_hits < PROBE_HITS:
            rate = clopper_pearson(n_hits, max(n_sim, 1), 0.90)[1]
            per_draw = clopper_pearson(n_hits, max(n_draws, 1), 0.90)[1]
            if (n_sim + self.mc_min_hits / rate > budget
                    or n_draws + self.mc_min_hits / per_draw > self.exact_draws):
                break
            n_hits, n_draws, n_sim = _add_batch(problem, kin, batch, rng, hits,
                                                (n_hits, n_draws, n_sim))
            batch = min(batch * 2, 1 << 18)
            if progress is not None:
                progress("pilot (plain Monte Carlo, probe)", n_hits, PROBE_HITS)
        probed = n_hits >= PROBE_HITS
        need = self.mc_min_hits * n_sim / n_hits if probed else math.inf
        n_plain = math.ceil(self.mc_min_hits * n_draws / n_hits) if probed else 0
        if not probed or n_sim + need > budget or n_draws + n_plain > self.exact_draws:
            # out of reach: the rare-event methods take over
            pilot.hits = np.concatenate(hits, axis=0)
            pilot.n_draws = n_draws
            pilot.n_simulated = n_sim
            return
        # 2. a fixed number of fresh draws, chosen from the probe's rate for mc_min_hits
        #    hits on average: the estimate comes from them alone, so it is binomial and
        #    unbiased with an exact interval (the probe stopped on its hits and was
        #    continued or given up on its rate: an estimate over its draws was measured
        #    biased high, 1.17 of the brute force over 9 seeds of the band with btn > 0.5)
        fresh: list[FloatArray] = []
        got = done = 0
        while done < n_plain:
            got, done, n_sim = _add_batch(problem, kin, min(1 << 18, n_plain - done), rng,
                                          fresh, (got, done, n_sim))
            if progress is not None:
                progress("pilot (plain Monte Carlo)", done, n_plain)
        pilot.hits = np.concatenate(fresh, axis=0)
        pilot.n_draws = n_plain
        pilot.n_simulated = n_sim
        pilot.probe_draws = n_draws
        pilot.plain = True

    def search(self, problem: Problem, rng: np.random.Generator, pilot: Pilot,
                need: int) -> None:
        found: list[FloatArray] = []
        total = 0
        for s in self.search_scales:
            z = problem.model.sample_z(self.search_draws, rng, scale=s)
            inside = z[problem.inside(z)]
            found.append(inside)
            total += self.search_draws
            if pilot.n_hits + sum(f.shape[0] for f in found) >= need:
                break
        pilot.search_hits = np.concatenate(found, axis=0)
        pilot.search_draws = total
        if pilot.n_hits == 0 and pilot.search_hits.shape[0] == 0:
            # one-sided upper bound of P(A and B): P(S) times the bound on P(A | S)
            p_up = problem.proposal_mass * upper_bound(0, pilot.n_draws, self.confidence)
            what = "model draws" if problem.envelope is None else (
                f"draws from the model restricted to the envelope {problem.envelope.source} "
                f"(mass {problem.envelope.mass:.3g})")
            raise EmptyRegionError(
                f"the region {problem.region.describe()} looks empty: none of "
                f"{pilot.n_draws} {what} and none of {total} draws from the model "
                f"widened by {', '.join(f'{s:g}x' for s in self.search_scales)} fell inside; "
                f"P(A and B) < {p_up:.2g} ({self.confidence:.0%} upper bound)",
                n_draws=pilot.n_draws + total, n_hits=0, p_upper=p_up)

    # ---------------------------------------------------------------- estimators

    def estimate(self, problem: Problem, rng: np.random.Generator, *, mc_draws: int,
                 mc_hits: int, region_z: FloatArray,
                 bounds: tuple[float, float, float], plain: bool = False) -> PRegion:
        """Choose ``mc`` or ``is`` (see the module docstring) and estimate P(A);
        ``plain``: the draws are a plain run of a size fixed in advance (the extended
        pilot's), so its estimate is used however few its hits (at least one)."""
        if mc_hits >= self.mc_min_hits or (plain and mc_hits > 0):
            out = self._plain(problem, mc_draws, mc_hits, bounds)
        else:
            out = self._importance(problem, rng, region_z, bounds)
        return self._not_empty(problem, out)

    def _plain(self, problem: Problem, mc_draws: int, mc_hits: int,
               bounds: tuple[float, float, float]) -> PRegion:
        """Plain MC (``mc``, or ``envelope`` for draws of the model restricted to one):
        ``mc_hits`` of ``mc_draws`` inside, exact (Clopper-Pearson) interval."""
        p_b, lo_b, hi_b = bounds
        mass = problem.proposal_mass  # P(S) of the envelope the draws came from, or 1
        lo, hi = clopper_pearson(mc_hits, mc_draws, self.confidence)
        joint = mass * mc_hits / mc_draws
        return PRegion(estimate=min(1.0, joint / p_b), ci_low=mass * lo / hi_b,
                       ci_high=min(1.0, mass * hi / lo_b), confidence=self.confidence,
                       method="mc" if problem.envelope is None else "envelope",
                       n_draws=mc_draws, n_hits=mc_hits, p_bounds=p_b,
                       p_bounds_ci=(lo_b, hi_b), p_joint=joint,
                       cov=math.sqrt((1 - mc_hits / mc_draws) / mc_hits) if mc_hits else None)

    def contradicts(self, problem: Problem, out: PRegion, pilot: Pilot | None) -> bool:
        """Whether a rare-event estimate ``out`` lies below what the pilot's exact plain
        draws prove: its upper end below their lower 99.9 % bound of P(A and B).

        Subset-is can miss most of a thin region (chains that barely move in a narrow
        band of a kinematic quantity; docs/sampler.md) and then reports a far too small
        P(A) with a narrow interval. The pilot's hits are exact, so a contradiction means
        the rare-event estimate is wrong, not unlucky (one-sided 1e-3 per check)."""
        if pilot is None or pilot.n_hits == 0 or pilot.n_draws == 0:
            return False
        lo, _ = clopper_pearson(pilot.n_hits, pilot.n_draws, 0.998)
        return out.ci_high * out.p_bounds_ci[0] < problem.proposal_mass * lo

    def from_subset(self, problem: Problem, result: Any,
                    bounds: tuple[float, float, float], pilot: Pilot | None = None
                    ) -> PRegion:
        """P(A) from a subset simulation (``sampler.methods.subset.SubsetResult``, method
        ``subset``) or subset-is (``sampler.methods.rare.RareResult``, method ``subset-is``).

        Interval: log-normal with ``cov_upper`` (subset: the conservative bound, levels
        fully correlated; subset-is: the importance sampler's CoV),
        ``p exp(+-z sqrt(log(1 + cov_upper^2)))``, combined with P(B)'s interval.

        With ``pilot``: when the estimate ``contradicts`` the pilot's exact draws, the
        pilot's plain estimate (exact interval, however few its hits) is returned
        instead."""
        p_b, lo_b, hi_b = bounds
        joint = float(result.probability)
        zc = float(stats.norm.ppf(0.5 + self.confidence / 2))
        s = math.sqrt(math.log1p(float(result.cov_upper) ** 2))
        out = PRegion(estimate=min(1.0, joint / p_b), ci_low=joint * math.exp(-zc * s) / hi_b,
                      ci_high=min(1.0, joint * math.exp(zc * s) / lo_b),
                      confidence=self.confidence,
                      method=str(getattr(result, "method", "subset")),
                      n_draws=int(result.n_evaluations), n_hits=int(result.z.shape[0]),
                      p_bounds=p_b, p_bounds_ci=(lo_b, hi_b), p_joint=joint,
                      cov=float(result.cov_upper))
        if pilot is not None and self.contradicts(problem, out, pilot):
            out = self._plain(problem, pilot.n_draws, pilot.n_hits, bounds)
        return self._not_empty(problem, out)

    def combine(self, parts: list[PRegion], bounds: tuple[float, float, float]) -> PRegion:
        """P(A) of a union of disjoint parts from their estimates (method ``split``):
        P(A and B) is the sum of theirs, its variance the sum of theirs (independent
        runs; a part's standard error is its CoV times its estimate, or, without a CoV,
        from its interval), and the interval is log-normal as in ``from_subset``."""
        p_b, lo_b, hi_b = bounds
        zc = float(stats.norm.ppf(0.5 + self.confidence / 2))
        joint = sum(p.p_joint for p in parts)
        var = 0.0
        for p in parts:
            if p.cov is not None:
                rel = p.cov
            elif p.estimate > 0:
                rel = (p.ci_high - p.ci_low) / (2 * zc * p.estimate)
            else:  # an empty part: its upper end as the standard error
                var += (p.ci_high * p.p_bounds / zc) ** 2
                continue
            var += (rel * p.p_joint) ** 2
        cov = math.sqrt(var) / joint if joint > 0 else math.inf
        s = math.sqrt(math.log1p(cov ** 2)) if joint > 0 else 0.0
        hi = (joint * math.exp(zc * s) if joint > 0 else math.sqrt(var) * zc) / lo_b
        return PRegion(estimate=min(1.0, joint / p_b), ci_low=joint * math.exp(-zc * s) / hi_b,
                       ci_high=min(1.0, hi), confidence=self.confidence, method="split",
                       n_draws=sum(p.n_draws for p in parts),
                       n_hits=sum(p.n_hits for p in parts), p_bounds=p_b,
                       p_bounds_ci=(lo_b, hi_b), p_joint=joint, cov=cov)

    def _not_empty(self, problem: Problem, out: PRegion) -> PRegion:
        """``out``, unless its upper bound is below ``min_p`` (EmptyRegionError)."""
        if out.ci_high < self.min_p:
            raise EmptyRegionError(
                f"the region {problem.region.describe()} is practically empty: {out}; "
                f"below min_p={self.min_p:g}", n_draws=out.n_draws, n_hits=out.n_hits,
                p_upper=out.ci_high)
        return out

    def _importance(self, problem: Problem, rng: np.random.Generator, region_z: FloatArray,
                    bounds: tuple[float, float, float]) -> PRegion:
        model = problem.model
        p_b, lo_b, hi_b = bounds
        pts = np.unique(region_z, axis=0)
        if pts.shape[0] < 2 * model.n_features + 2:
            raise EmptyRegionError(
                f"only {pts.shape[0]} distinct points inside {problem.region.describe()}: "
                "too few to build an importance-sampling proposal", n_hits=pts.shape[0])
        prop = MixtureProposal(model, pts, int(rng.integers(0, 2**31 - 1)), max_k=3,
                                inflate=self.inflate, alpha=self.defensive)
        n = self.n_is
        z = prop.draw(n, rng)
        w = np.exp(model.log_density_z(z) - prop.log_q(z))
        inside = problem.inside(z)
        f = np.where(inside, w, 0.0)
        joint = float(f.mean())
        se = float(f.std(ddof=1) / math.sqrt(n))
        zc = float(stats.norm.ppf(0.5 + self.confidence / 2))
        lo_j, hi_j = max(0.0, joint - zc * se), joint + zc * se
        return PRegion(estimate=min(1.0, joint / p_b), ci_low=lo_j / hi_b,
                       ci_high=min(1.0, hi_j / lo_b), confidence=self.confidence, method="is",
                       n_draws=n, n_hits=int(inside.sum()), p_bounds=p_b,
                       p_bounds_ci=(lo_b, hi_b), p_joint=joint,
                       cov=se / joint if joint > 0 else None)
