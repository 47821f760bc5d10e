"""A campaign: a system under test driven through importance-sampled cut-ins, and its
collision probability per cut-in and rate per hour (docs/evaluation.md).

Target: the model restricted to the physical bounds B (and to a user's region A when
``constraints`` are given), the law every other part of scengen samples. With runs
``z_i ~ q`` (``sampler.campaign.proposal``), ``w_i = p(z_i) / q(z_i)`` (both exact,
normalised densities in the model's z-space) and ``c_i`` = 1 if run i lies in A and B and
collided::

    P(C and A | B) = (1 / N) sum_i w_i c_i / P(B)

over all N draws (a draw outside A or B is not simulated and counts 0). ``P(B)`` is the
model's mass inside the bounds, from 2^18 plain draws (no simulation; its own relative
error, about 1e-3, enters the standard error). Chunk k's proposal is fixed before its draws
(it depends on the chunks before it only), so every term has expectation P given the past
and the pooled mean is unbiased.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp
from scipy.stats import norm

from datasets import PARAM_NAMES
from sampler.campaign.proposal import (
    BAND_STEP_HITS_SHARE,
    BAND_STEP_KERNEL_SHARE,
    BAND_STEP_SET_SHARE,
    DEFAULT_ENVELOPES,
    BandPool,
    Proposal,
    build_ce_proposal,
    build_proposal,
    campaign_envelopes,
)
from sampler.campaign.reliability import verdict
from sampler.campaign.runners import Runner
from sampler.errors import SamplerError
from sampler.model.bootstrap import log_density_z_boot, pooled_model
from sampler.model.gmm import CutInGMM
from sampler.model.memo import MODEL_SEED, memoised
from sampler.rates.bootstrap_interval import bootstrap_ci
from sampler.rates.exposure import Exposure
from sampler.region.constraints import Region
from sampler.sampling import estimate_p_region

__all__ = ["CampaignResult", "ChunkResult", "evaluate", "next_ce_proposal"]

FloatArray = NDArray[np.float64]
#: progress callback: (stage, runs done, runs planned)
ProgressFn = Callable[[str, int, int], None]

#: plain model draws behind P(B) (no simulation)
N_BOUNDS = 1 << 18
#: draws of the replicates' average behind each replicate's P_b(B)
N_BOUNDS_BOOT = 1 << 16
#: the collisions the stop rule needs besides the relative half-width
MIN_COLLISIONS = 10
#: the stop rule's relative half-width of the 95 % interval when a campaign gives neither
#: ``n`` nor ``rhw`` (``evaluate``, ``POST /evaluations``, ``scengen evaluate``): at
#: P ~ 1e-5 the reported interval covered P in 83 % of 120 campaigns with 0.3, 90 % of 80
#: with 0.15 (docs/evaluation.md, "How tight a stop rule"). A stored evaluation's spec
#: always holds its rhw, so changing this does not change a resumed job. ``scengen
#: evaluate`` writes it out (``app.cli.evaluate.DEFAULT_RHW``, so that its --help imports
#: no sampler); tests/app/test_stop_rule_default.py fails if the two differ
DEFAULT_RHW = 0.15
#: -ln(0.05): the one-sided 95 % "rule of three" factor
RULE_OF_THREE = -math.log(0.05)


# --------------------------------------------------------------------------- chunks

def _enc(a: NDArray[Any]) -> dict[str, Any]:
    """A (n,) or (n, d) array as JSON-safe lists, lossless (floats by repr; non-finite
    as the strings "nan", "inf", "-inf")."""
    if a.dtype == np.bool_:
        return {"dtype": "bool", "values": a.astype(bool).tolist()}
    if a.dtype.kind in "iu":
        return {"dtype": str(a.dtype), "values": a.tolist()}
    if a.dtype.kind in "US":
        return {"dtype": "str", "values": a.astype(str).tolist()}
    if a.dtype.kind == "O":
        return {"dtype": "str", "values": [str(v) for v in a.tolist()]}
    f = np.asarray(a, dtype=np.float64)

    def one(v: float) -> float | str:
        return v if math.isfinite(v) else ("nan" if v != v else ("inf" if v > 0 else "-inf"))

    if f.ndim == 1:
        return {"dtype": "float64", "values": [one(v) for v in f.tolist()]}
    return {"dtype": "float64", "values": [[one(v) for v in row] for row in f.tolist()]}


def _dec(d: Mapping[str, Any]) -> NDArray[Any]:
    dtype = d["dtype"]
    if dtype == "bool":
        return np.asarray(d["values"], dtype=bool)
    if dtype == "str":
        return np.asarray(d["values"], dtype=str)
    if dtype == "float64":
        def one(v: Any) -> float:
            return float(v)  # float("nan"), float("inf") parse the strings
        vals = d["values"]
        if vals and isinstance(vals[0], list):
            return np.asarray([[one(v) for v in row] for row in vals], dtype=np.float64)
        return np.asarray([one(v) for v in vals], dtype=np.float64)
    return np.asarray(d["values"], dtype=np.dtype(dtype))


@dataclass
class ChunkResult:
    """One chunk of a campaign: its draws, weights and outcomes (arrays of n rows).

    ``params`` (n, 8) in ``PARAM_NAMES`` order; ``z`` (n, d) the model's z-space rows;
    ``seeds`` (n,) uint64; ``part`` the proposal part each row came from (index into
    ``proposal``); ``log_p``, ``log_q`` the model's and the proposal's log-densities in
    z-space; ``weights = exp(log_p - log_q)``; ``simulated`` the rows inside the region
    and the bounds (the others were not run); ``outcome`` name -> (n,) array (``collided``,
    ``impact_speed`` and whatever else the runner gave; rows not run: False / 0 / NaN / "").
    With weight roulette (``roulette_t > 0``) a row inside the region was run only with
    probability ``min(1, w / roulette_t)`` (``exp(log_keep)``); ``log_q`` then includes
    ``log_keep`` (the density of the rows that were run), so ``weights`` are those of the
    rows run, and ``skipped`` counts the rows inside the region that were not.
    """

    index: int
    params: FloatArray
    z: FloatArray
    seeds: NDArray[np.uint64]
    part: NDArray[np.int64]
    log_p: FloatArray
    log_q: FloatArray
    weights: FloatArray
    simulated: NDArray[np.bool_]
    outcome: dict[str, NDArray[Any]]
    proposal: list[dict[str, Any]] = field(default_factory=list)
    #: False for a pilot chunk of an adaptive cross-entropy campaign (its runs shape the
    #: proposal but are left out of the estimate; decided before its draws)
    counted: bool = True
    #: weight roulette's threshold (0: every row inside the region was run)
    roulette_t: float = 0.0
    #: log of each row's probability to be run under the roulette (None without it)
    log_keep: FloatArray | None = None
    #: rows inside the region and the bounds the roulette left unrun
    skipped: int = 0

    @property
    def n(self) -> int:
        return int(self.weights.shape[0])

    @property
    def collided(self) -> NDArray[np.bool_]:
        return np.asarray(self.outcome["collided"], dtype=bool) & self.simulated

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe and lossless (``from_dict`` gives back equal arrays, bit for bit)."""
        return {
            "format": "scengen.campaign-chunk/1",
            "index": int(self.index),
            "params": _enc(self.params), "z": _enc(self.z),
            "seeds": [int(s) for s in self.seeds.tolist()],
            "part": _enc(self.part), "log_p": _enc(self.log_p), "log_q": _enc(self.log_q),
            "weights": _enc(self.weights), "simulated": _enc(self.simulated),
            "outcome": {k: _enc(v) for k, v in self.outcome.items()},
            "proposal": list(self.proposal),
            "counted": bool(self.counted),
            **({"roulette_t": float(self.roulette_t), "log_keep": _enc(self.log_keep),
                "skipped": int(self.skipped)}
               if self.roulette_t > 0 and self.log_keep is not None else {}),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ChunkResult:
        try:
            if d.get("format") != "scengen.campaign-chunk/1":
                raise SamplerError(f"chunk: unknown format {d.get('format')!r}",
                                   field="format")
            return cls(index=int(d["index"]), params=_dec(d["params"]), z=_dec(d["z"]),
                       seeds=np.asarray(d["seeds"], dtype=np.uint64),
                       part=_dec(d["part"]).astype(np.int64), log_p=_dec(d["log_p"]),
                       log_q=_dec(d["log_q"]), weights=_dec(d["weights"]),
                       simulated=_dec(d["simulated"]),
                       outcome={str(k): _dec(v) for k, v in d["outcome"].items()},
                       proposal=list(d.get("proposal", [])),
                       counted=bool(d.get("counted", True)),
                       roulette_t=float(d.get("roulette_t", 0.0)),
                       log_keep=_dec(d["log_keep"]) if "log_keep" in d else None,
                       skipped=int(d.get("skipped", 0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise SamplerError(f"chunk: not a stored campaign chunk ({exc})",
                               field="chunk") from None


def _outcome_arrays(batch: Any, m: int) -> dict[str, NDArray[Any]]:
    """The (m,) array attributes of a runner's result (``profiles`` and scalars left out)."""
    arrays = getattr(batch, "arrays", None)
    if isinstance(arrays, Mapping):
        names = list(arrays)
    elif is_dataclass(batch):
        names = [f.name for f in fields(batch)]
    else:
        names = [k for k in vars(batch) if not k.startswith("_")]
    out: dict[str, NDArray[Any]] = {}
    for name in names:
        v = getattr(batch, name, None)
        if isinstance(v, np.ndarray) and v.ndim == 1 and v.shape[0] == m:
            out[name] = v
    if "collided" not in out or "impact_speed" not in out:
        raise SamplerError("runner: its result needs (n,) arrays collided and impact_speed",
                           field="runner")
    return out


def _fill(values: NDArray[Any], rows: NDArray[np.int64], n: int, name: str) -> NDArray[Any]:
    if values.dtype == np.bool_:
        out: NDArray[Any] = np.zeros(n, dtype=bool)
    elif values.dtype.kind in "iu":
        out = np.zeros(n, dtype=values.dtype)
    elif values.dtype.kind in "USO":
        out = np.full(n, "", dtype=object)
    else:
        out = np.full(n, 0.0 if name == "impact_speed" else np.nan)
    out[rows] = values
    if out.dtype == object:
        out = out.astype(str)
    return out


def _run(runner: Runner, params: FloatArray, seeds: NDArray[np.uint64],
         executor: Executor | None, part_size: int) -> dict[str, NDArray[Any]]:
    m = params.shape[0]
    if executor is None or m <= part_size:
        return _outcome_arrays(runner(params, seeds), m)
    cuts = list(range(0, m, part_size))
    futures = [executor.submit(runner, params[i:i + part_size], seeds[i:i + part_size])
               for i in cuts]
    parts = [_outcome_arrays(f.result(), min(part_size, m - i))
             for f, i in zip(futures, cuts, strict=True)]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


# --------------------------------------------------------------------------- figures

def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _p_bounds(model: CutInGMM, region: Region) -> tuple[float, float]:
    """P(B) and its relative standard error (exactly 1, 0 without physical bounds)."""
    if not region.physical_bounds:
        return 1.0, 0.0

    def compute() -> int:
        z = model.sample_z(N_BOUNDS, np.random.default_rng(MODEL_SEED))
        return int(region.in_bounds(model.params_matrix(model.from_z(z))).sum())

    k = memoised(model, ("campaign_p_bounds", region.lane_width, N_BOUNDS), compute)
    if k == 0:
        raise SamplerError("no model draw satisfies the physical bounds: the model does not "
                           "describe physical cut-ins", field="model")
    p = k / N_BOUNDS
    return p, math.sqrt((1 - p) / (N_BOUNDS * p))


def _p_bounds_boot(model: CutInGMM, region: Region) -> FloatArray:
    """Each bootstrap replicate's P_b(B), by reweighting draws of the replicates' average
    ``qb = (1/B) sum_b p_b`` (``p_b / qb <= B``): shape (B,)."""
    n_boot = len(model.bootstrap_["weights"]) if model.bootstrap_ else 0
    if not region.physical_bounds:
        return np.ones(n_boot)

    def compute() -> FloatArray:
        pooled = memoised(model, ("campaign_pooled",), lambda: pooled_model(model))
        z = pooled.sample_z(N_BOUNDS_BOOT, np.random.default_rng(MODEL_SEED + 1))
        inb = region.in_bounds(model.params_matrix(model.from_z(z)))
        lp = log_density_z_boot(model, z[inb])
        lq = logsumexp(lp, axis=0) - math.log(lp.shape[0])
        return np.asarray(np.exp(lp - lq).sum(axis=1) / N_BOUNDS_BOOT, dtype=np.float64)

    out: FloatArray = memoised(model, ("campaign_p_bounds_boot", region.lane_width,
                                       N_BOUNDS_BOOT), compute)
    return out


@dataclass
class _Estimate:
    estimate: float
    se: float
    n: int
    hits: int
    ess: float


def _estimate(chunks: Sequence[ChunkResult], key: str, pb: float, cv_b: float) -> _Estimate:
    n = sum(c.n for c in chunks)
    ys = [np.where(c.simulated & np.asarray(c.outcome.get(key, np.zeros(c.n, dtype=bool)),
                                            dtype=bool), c.weights, 0.0) for c in chunks]
    y = np.concatenate(ys) if ys else np.zeros(0)
    hits = int(np.count_nonzero(y))
    if n == 0:
        return _Estimate(math.nan, math.nan, 0, 0, 0.0)
    p = float(y.sum() / n / pb)
    sd = float(y.std(ddof=1)) if n > 1 else math.nan
    se = math.sqrt((sd / math.sqrt(n) / pb) ** 2 + (p * cv_b) ** 2)
    ess = float(y.sum() ** 2 / (y * y).sum()) if hits else 0.0
    return _Estimate(p, se, n, hits, ess)


def _lognormal_ci(p: float, cv: float, z: float) -> list[float | None]:
    if not (p > 0 and math.isfinite(cv)):
        return [None, None]
    return [_num(p * math.exp(-z * cv)), _num(p * math.exp(z * cv))]


@dataclass
class CampaignResult:
    """The chunks of a campaign and its figures (``summary()``, ``records()``)."""

    chunks: list[ChunkResult]
    stop_reason: str
    model: CutInGMM = field(repr=False)
    region: Region = field(repr=False)
    seed: int = 0
    sut: str | None = None
    exposure: Exposure | None = None
    bootstrap: bool = True
    confidence: float = 0.95
    rhw_target: float | None = DEFAULT_RHW
    alpha: float = 0.15
    #: the model's share in the final stage of an adaptive cross-entropy campaign
    #: (``evaluate(final_alpha=...)``; None: ``alpha``), as run
    final_alpha: float | None = None
    p_region: Any = None  # PRegion of the user's region (None without constraints)
    adapt: str = "kernels"
    #: the final stage's band step (``evaluate(band_step=...)``), as run
    band_step: bool = False
    #: weight roulette's factor (``evaluate(roulette=...)``; 0: off), as run
    roulette: float = 0.0
    _summary: dict[str, Any] | None = field(default=None, repr=False)

    @property
    def runs(self) -> int:
        return sum(c.n for c in self.chunks)

    @property
    def counted_chunks(self) -> list[ChunkResult]:
        """The chunks the estimate uses (:func:`_counted`)."""
        return _counted(self.chunks)

    @property
    def counted_runs(self) -> int:
        return sum(c.n for c in self.counted_chunks)

    @property
    def bound_alpha(self) -> float:
        """The model's smallest share in the chunks the estimate uses (every counted draw's
        ``q >= bound_alpha p``: the no-collision bound's factor): ``final_alpha`` once a
        cross-entropy campaign counts its final stage, else ``alpha``."""
        counted = [c.counted for c in self.chunks]
        if (self.final_alpha is not None and self.adapt == "ce" and any(counted)
                and not all(counted)):
            return min(self.alpha, self.final_alpha)
        return self.alpha

    @property
    def sut_runs(self) -> int:
        return sum(int(c.simulated.sum()) for c in self.chunks)

    def _model_replicates(self, key: str, pb_b: FloatArray) -> FloatArray | None:
        """P_b(key and A | B) of each bootstrap replicate from the same runs:
        ``(1/N) sum_i w_i c_i p_b(z_i) / p(z_i) / P_b(B)``, with ``w_i p_b / p = p_b / q``
        evaluated as one exponent (``p_b / p`` alone overflows where p is far smaller
        than a replicate, and ``w`` underflows there: inf times 0)."""
        n = self.counted_runs
        zs, lqs = [], []
        for c in self.counted_chunks:
            sel = c.simulated & np.asarray(c.outcome.get(key, np.zeros(c.n, dtype=bool)),
                                           dtype=bool)
            zs.append(c.z[sel])
            lqs.append(c.log_q[sel])
        z = np.concatenate(zs)
        if not z.shape[0]:
            return np.zeros(pb_b.shape[0])
        lpb = log_density_z_boot(self.model, z)  # (B, m)
        r = np.exp(lpb - np.concatenate(lqs)[None, :])
        return np.asarray(r.sum(axis=1) / n / pb_b, dtype=np.float64)

    def summary(self) -> dict[str, Any]:
        """The campaign's figures, JSON-safe (None for undefined); docs/evaluation.md."""
        if self._summary is not None:
            return self._summary
        zq = float(norm.ppf(0.5 + self.confidence / 2))
        pb, cv_b = _p_bounds(self.model, self.region)
        col = _estimate(self.counted_chunks, "collided", pb, cv_b)
        has_boot = bool(self.bootstrap and getattr(self.model, "bootstrap_", None))
        pb_b = _p_bounds_boot(self.model, self.region) if has_boot else None
        # the user's region: P(A | B) from the existing machinery, and its relative error
        pa, cv_a = 1.0, 0.0
        if self.p_region is not None:
            pa = float(self.p_region.estimate)
            lo, hi = float(self.p_region.ci_low), float(self.p_region.ci_high)
            cv_a = ((math.log(hi) - math.log(lo)) / (2 * zq)
                    if lo > 0 and hi > 0 and pa > 0 else math.inf)

        def block(est: _Estimate, key: str) -> tuple[dict[str, Any], FloatArray | None]:
            p_joint = est.estimate
            cv_joint = est.se / p_joint if p_joint > 0 else math.inf
            p = p_joint / pa
            cv = math.sqrt(cv_joint ** 2 + cv_a ** 2)
            reps = None
            if pb_b is not None:
                reps = self._model_replicates(key, pb_b)
            model_ci: list[float | None] | None = None
            if reps is not None and self.p_region is None and p > 0:
                lo, hi = bootstrap_ci(reps, p, method="percentile",
                                      confidence=self.confidence)
                model_ci = [_num(lo), _num(hi)]
            upper = None
            if est.hits == 0 and self.counted_runs > 0:  # a probability: at most 1
                upper = min(RULE_OF_THREE / (self.bound_alpha * self.counted_runs * pb) / pa,
                            1.0)
            out = {"estimate": _num(p), "ci": _lognormal_ci(p, cv, zq), "model_ci": model_ci,
                   "se": _num(p * cv) if p > 0 else _num(est.se / pa),
                   "rhw": _num(zq * cv) if p > 0 else None,
                   "upper_bound": _num(upper), "hits": est.hits, "ess": _num(est.ess)}
            return out, reps

        p_col, reps_col = block(col, "collided")
        viol_known = all("violation" in c.outcome for c in self.chunks) and self.chunks
        p_viol = block(_estimate(self.counted_chunks, "violation", pb, cv_b), "violation")[0] \
            if viol_known else None
        # rates: lambda P(C and A | B), the count's Poisson replicates in the model interval
        rates: dict[str, Any] = {"rate_per_hour": None, "rate_per_1e6_km": None}
        if self.exposure is not None:
            exp = self.exposure
            counts = np.random.default_rng(self.seed).poisson(
                exp.n_events, size=0 if reps_col is None else reps_col.size)
            p_joint = col.estimate
            cv_joint = col.se / p_joint if p_joint > 0 else math.inf
            for unit, amount in (("rate_per_hour", exp.hours),
                                 ("rate_per_1e6_km", None if exp.km is None else exp.km / 1e6)):
                if amount is None:
                    continue
                lam = exp.n_events / amount
                entry: dict[str, Any] = {
                    "estimate": _num(lam * p_joint),
                    "ci": _lognormal_ci(lam * p_joint, cv_joint, zq),
                    "model_ci": None,
                    "upper_bound": None if col.hits else _num(min(
                        RULE_OF_THREE / (self.bound_alpha * self.counted_runs * pb), 1.0)
                        * lam)
                    if self.counted_runs else None}
                if reps_col is not None and p_joint > 0:
                    r = reps_col * counts / amount
                    a = 1.0 - self.confidence
                    q = np.quantile(r[np.isfinite(r)], [a / 2, 1 - a / 2])
                    entry["model_ci"] = [_num(q[0]), _num(q[1])]
                rates[unit] = entry
        n_sim = self.sut_runs
        p_c = col.estimate
        accel = (p_c * (1 - p_c) / (n_sim * col.se ** 2)
                 if n_sim and col.hits and col.se > 0 else None)
        self._summary = {
            "p_collision": p_col,
            **rates,
            "p_violation": p_viol,
            "runs": self.runs,
            "sut_runs": n_sim,
            "pilot_runs": self.runs - self.counted_runs,
            "adapt": self.adapt,
            "band_step": self.band_step,
            "roulette": self.roulette,
            "alpha": self.alpha,
            "final_alpha": self.final_alpha if self.adapt == "ce" else None,
            "skipped_runs": sum(c.skipped for c in self.chunks),
            "proposal": self.chunks[-1].proposal if self.chunks else [],
            "collisions": col.hits,
            "ess": _num(col.ess),
            "acceleration": _num(accel),
            "stop_reason": self.stop_reason,
            "sut": self.sut,
            "constraints": [str(c) for c in self.region.constraints],
            "region_probability": None if self.p_region is None else {
                "estimate": _num(self.p_region.estimate),
                "ci": [_num(self.p_region.ci_low), _num(self.p_region.ci_high)]},
            "p_bounds": _num(pb),
            "seed": self.seed,
            "chunks": len(self.chunks),
            "confidence": self.confidence,
            "rhw_target": self.rhw_target,
            "exposure": None if self.exposure is None else self.exposure.to_dict(),
        }
        self._summary.update(verdict(self._summary))  # warnings, reliable: reliability.py
        return self._summary

    def records(self) -> list[dict[str, Any]]:
        """One dict per run: ``run``, ``chunk``, ``seed``, the parameters by name,
        ``weight`` (its weight in P: ``w / P(B)``), ``log_p``, ``log_q``, ``part`` (the
        proposal it came from), ``simulated``, ``counted`` (its chunk is one the estimate
        uses: :attr:`counted_chunks`), ``keep_prob`` (with weight roulette: the
        probability the row had to be run) and the outcome fields."""
        pb, _ = _p_bounds(self.model, self.region)
        used = {c.index for c in self.counted_chunks}
        out: list[dict[str, Any]] = []
        run = 0
        for c in self.chunks:
            names = [str(p.get("part", "")) for p in c.proposal]
            for i in range(c.n):
                rec: dict[str, Any] = {"run": run, "chunk": c.index, "seed": int(c.seeds[i])}
                rec.update({k: float(v) for k, v in zip(PARAM_NAMES, c.params[i].tolist(),
                                                         strict=True)})
                rec["weight"] = float(c.weights[i] / pb)
                rec["log_p"] = float(c.log_p[i])
                rec["log_q"] = float(c.log_q[i])
                k = int(c.part[i])
                rec["part"] = names[k] if 0 <= k < len(names) else k
                rec["simulated"] = bool(c.simulated[i])
                rec["counted"] = c.index in used
                if c.log_keep is not None:
                    rec["keep_prob"] = float(np.exp(c.log_keep[i]))
                for name, arr in c.outcome.items():
                    v = arr[i]
                    rec[name] = (bool(v) if arr.dtype == np.bool_ else str(v)
                                 if arr.dtype.kind in "US" else _num(v))
                out.append(rec)
                run += 1
        return out


# --------------------------------------------------------------------------- evaluate

def _region(model: CutInGMM, constraints: Any, physical_bounds: bool) -> Region:
    lane = float(getattr(model, "lane_width_", None) or 3.75)
    if constraints is None:
        region = Region.from_constraints((), lane_width=lane, physical_bounds=physical_bounds)
    elif isinstance(constraints, Region):
        region = constraints
    else:
        region = Region.from_constraints(list(constraints), lane_width=lane,
                                         physical_bounds=physical_bounds)
    return region.bind(model)


def _hits(chunks: Sequence[ChunkResult]) -> tuple[FloatArray, FloatArray] | None:
    zs = [c.z[c.collided] for c in chunks]
    ws = [c.weights[c.collided] for c in chunks]
    if not zs:
        return None
    z = np.concatenate(zs)
    return (z, np.concatenate(ws)) if z.shape[0] else None


def _counted(chunks: Sequence[ChunkResult]) -> list[ChunkResult]:
    """The chunks the estimate uses: those flagged ``counted``; all of them when none is
    (a cross-entropy campaign stopped at ``max_runs`` before its final stage: every
    chunk is still an importance sample of p under its own proposal) or when the runner
    gives no performance score (a cross-entropy campaign that adapted as ``kernels``
    from its second chunk on: its first chunk counts as a kernels campaign's does)."""
    out = [c for c in chunks if c.counted]
    return out if out and not _unscored(chunks) else list(chunks)


def performance_score(outcome: Mapping[str, NDArray[Any]], simulated: NDArray[np.bool_]
                      ) -> FloatArray | None:
    """A continuous performance score per run, at most 0 exactly for the collided runs
    (lower: closer to a collision), or None when the runner gives none:

    * ``margin`` when the runner reports it (the stand-ins: the signed distance to the
      collision set, <= 0 iff collided);
    * else ``min_gap`` (m, the SUT's smallest clearance ahead) for runs without
      contact and ``-impact_speed`` (m/s) for collided runs (a harder impact is worse).

    Rows not simulated, NaN and +inf score +inf (never elite)."""
    collided = np.asarray(outcome["collided"], dtype=bool) & simulated
    if "margin" in outcome:
        s = np.asarray(outcome["margin"], dtype=np.float64).copy()
    elif "min_gap" in outcome:
        gap = np.asarray(outcome["min_gap"], dtype=np.float64)
        s = np.where(collided, -np.asarray(outcome["impact_speed"], dtype=np.float64), gap)
    else:
        return None
    s = np.where(~collided & (s <= 0), 1e-9, s)  # touching without contact is not <= 0
    s = np.where(simulated & np.isfinite(s), s, np.inf)
    return np.asarray(np.where(collided, np.minimum(s, 0.0), s), dtype=np.float64)


def _unscored(chunks: Sequence[ChunkResult]) -> bool:
    """Whether the runner gives no performance score, judged on the first chunk that ran
    rows (a runner's outcome fields do not change between calls; a cross-entropy campaign
    then adapts as ``kernels`` does). False before any row ran."""
    for c in chunks:
        if bool(np.any(c.simulated)):
            return performance_score(c.outcome, c.simulated) is None
    return False


def _ce_elite(previous: Sequence[ChunkResult], rho: float, min_hits: int
              ) -> tuple[tuple[FloatArray, FloatArray] | None, float, bool, BandPool | None]:
    """The cross-entropy step's elite from the runs so far (multi-level: Rubinstein &
    Kroese 2004): with at least ``min_hits`` collided runs the elite are the collided
    runs (level 0, final stage); else the runs so far whose score is at most the
    ``rho``-quantile gamma of the last chunk's scores (level gamma > 0, a pilot stage).
    Returns (z rows and weights p/q of the elite, or None; the level; final stage?;
    in the final stage all the runs so far with their scores, for the bands' own step)."""
    zs, ws, ss = [], [], []
    drawn: dict[str, int] = {}
    for c in previous:
        sc = performance_score(c.outcome, c.simulated)
        if sc is None:
            return None, math.inf, False, None
        zs.append(c.z)
        ws.append(c.weights)
        ss.append(sc)
        counts = np.bincount(c.part, minlength=len(c.proposal))
        for j, row in enumerate(c.proposal):
            drawn[row["part"]] = drawn.get(row["part"], 0) + int(counts[j])
    if not zs:
        return None, math.inf, False, None
    z, w, s = np.concatenate(zs), np.concatenate(ws), np.concatenate(ss)
    hit = s <= 0
    if int(hit.sum()) >= min_hits:
        return (z[hit], w[hit]), 0.0, True, BandPool(z, w, s, drawn)
    gamma = float(np.quantile(ss[-1], rho, method="inverted_cdf"))
    if not math.isfinite(gamma):
        return None, math.inf, False, None
    sel = s <= gamma
    return (z[sel], w[sel]), gamma, False, None


#: the largest defensive share of the model a campaign takes (the final stage's other
#: parts take the rest: ``sampler.campaign.proposal.build_ce_proposal``)
MAX_ALPHA = 0.2
#: the largest weight-roulette factor ``evaluate()`` takes (a threshold far above
#: P_hat would leave most runs of the proposal's right places unrun)
MAX_ROULETTE = 100.0
#: the weight-roulette factor of a new campaign of the CLI and the API with adapt "ce"
#: (``evaluate()`` itself runs without unless asked): docs/evaluation.md, "Weight roulette"
DEFAULT_ROULETTE = 5.0
#: the model's final-stage share of a new campaign of the CLI and the API that runs the
#: weight roulette (``evaluate(final_alpha=...)``): docs/evaluation.md, "A smaller
#: defensive share in the final stage"
ROULETTE_FINAL_ALPHA = 0.05
#: share of the earlier pilot levels' mixtures in a cross-entropy chunk's proposal
CE_HISTORY_SHARE = 0.1
#: ... in the final stage with ``band_step``: its collided runs lead, the pilot levels
#: keep less
BAND_STEP_HISTORY_SHARE = 0.05
#: scale factor of the cross-entropy mixture's components
CE_INFLATE = 1.2


def _ce_proposal(k: int, model: CutInGMM, region: Region, seed: int,
                 previous: Sequence[ChunkResult], envelopes: Sequence[str], alpha: float,
                 rho: float, ce_min_hits: int, fits: dict[int, tuple[Any, float]],
                 band_step: bool = False, tune_shares: bool = False,
                 final_alpha: float | None = None
                 ) -> tuple[Proposal, bool, np.random.Generator]:
    """Chunk k's cross-entropy proposal from the chunks before it, and whether it counts.

    Besides the mixture fitted at this chunk's level it keeps, with share
    ``CE_HISTORY_SHARE``, the equal mixture of the mixtures fitted at the earlier pilot
    levels (``fits``: chunk index -> (its fitted mixture or None, its level), filled here;
    a chunk replayed from storage is refitted from the chunks before it with its own
    generator, which gives the same mixture bit for bit). The generator is returned as
    the fit left it: the chunk's draws continue it. The model's share is ``alpha`` in
    the pilot and ``final_alpha`` (None: ``alpha``) in the final stage."""
    def build(j: int, history: list[Any]
              ) -> tuple[Proposal, bool, float, np.random.Generator]:
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(j)]))
        elite, level, counted, pool = _ce_elite(previous[:j], rho, ce_min_hits)
        shares: dict[str, Any] = {"history_share": CE_HISTORY_SHARE}
        if band_step and level <= 0:
            shares = {"history_share": BAND_STEP_HISTORY_SHARE, "pool": pool,
                      "set_share": BAND_STEP_SET_SHARE,
                      "band_hits_share": BAND_STEP_HITS_SHARE,
                      "kernel_share": BAND_STEP_KERNEL_SHARE}
        prop = build_ce_proposal(model, region=region, lane_width=region.lane_width,
                                 elite=elite, level=level, rng=rng, envelopes=envelopes,
                                 alpha=final_alpha if counted and final_alpha is not None
                                 else alpha, history=history, inflate=CE_INFLATE,
                                 tune=tune_shares, **shares)
        return prop, counted, level, rng

    def history(j: int) -> list[Any]:
        out = []
        for i in range(j):
            if i not in fits and previous[i].counted and i > 0:
                continue  # a final-stage chunk (level 0): not a pilot level
            if i not in fits:
                prop, _, level, _ = build(i, history(i))
                fits[i] = (prop.fitted, level)
            gm, level = fits[i]
            if gm is not None and level > 0:
                out.append(gm)
        return out

    prop, counted, level, rng = build(k, history(k))
    fits[k] = (prop.fitted, level)
    return prop, counted, rng


def next_ce_proposal(result: CampaignResult, *, envelopes: Sequence[str] = DEFAULT_ENVELOPES,
                     alpha: float = 0.15, rho: float = 0.1, ce_min_hits: int = 20,
                     band_step: bool = False, tune_shares: bool = False,
                     final_alpha: float | None = None) -> Proposal:
    """The proposal the next chunk of a cross-entropy campaign would draw from, rebuilt
    from its chunks as ``evaluate`` builds it (pass the settings the campaign ran with):
    for diagnostics such as ``benchmarks/bench_true_efficiency.py``."""
    prop, _, _ = _ce_proposal(len(result.chunks), result.model, result.region, result.seed,
                              result.chunks, campaign_envelopes(envelopes, band_step), alpha,
                              rho, ce_min_hits, {},
                              band_step, tune_shares, final_alpha)
    return prop


def _new_chunk(k: int, size: int, model: CutInGMM, region: Region, runner: Runner,
               seed: int, previous: Sequence[ChunkResult], envelopes: Sequence[str],
               alpha: float, executor: Executor | None, part_size: int,
               min_fit_hits: int, adapt: str = "kernels", rho: float = 0.1,
               ce_min_hits: int = 10, ce_fits: dict[int, tuple[Any, float]] | None = None,
               band_step: bool = False, tune_shares: bool = False,
               roulette: float = 0.0, final_alpha: float | None = None) -> ChunkResult:
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(k)]))
    counted = True
    proposal: Proposal
    threshold = 0.0
    if adapt == "ce" and not _unscored(previous):
        proposal, counted, rng = _ce_proposal(k, model, region, seed, previous, envelopes,
                                              alpha, rho, ce_min_hits,
                                              {} if ce_fits is None else ce_fits, band_step,
                                              tune_shares, final_alpha)
        if counted:
            threshold = roulette_threshold(previous, roulette)
    else:
        hits = _hits(previous)
        if hits is not None and hits[0].shape[0] < min_fit_hits:
            hits = None
        proposal = build_proposal(model, region=region, lane_width=region.lane_width,
                                  envelopes=envelopes, hits=hits, rng=rng, alpha=alpha)
    z, part = proposal.draw(size, rng)
    seeds = rng.integers(0, np.iinfo(np.uint64).max, size=size, dtype=np.uint64,
                         endpoint=True)
    log_p = model.log_density_z(z)
    log_q = proposal.log_q(z)
    weights = np.exp(log_p - log_q)
    params = model.params_matrix(model.from_z(z))
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        inside = np.asarray(region.contains(params), dtype=bool)
    log_keep: FloatArray | None = None
    skipped = 0
    if threshold > 0:
        # weight roulette: a row whose weight is below the threshold is run with
        # probability w / threshold and then weighs the threshold (its weight over that
        # probability): the rows run are an importance sample of q min(1, w / t)
        u = rng.random(size)
        with np.errstate(over="ignore"):
            log_keep = np.minimum(0.0, log_p - log_q - math.log(threshold))
        keep = u < np.exp(log_keep)
        skipped = int(np.count_nonzero(inside & ~keep))
        inside = inside & keep
        log_q = log_q + log_keep
        weights = np.exp(log_p - log_q)
    rows = np.flatnonzero(inside)
    outcome: dict[str, NDArray[Any]]
    if rows.size:
        got = _run(runner, params[rows], seeds[rows], executor, part_size)
        outcome = {name: _fill(v, rows, size, name) for name, v in got.items()}
    else:
        outcome = {"collided": np.zeros(size, dtype=bool), "impact_speed": np.zeros(size)}
    return ChunkResult(index=k, params=params, z=z, seeds=seeds, part=part, log_p=log_p,
                       log_q=log_q, weights=weights, simulated=inside, outcome=outcome,
                       proposal=proposal.describe(), counted=counted,
                       roulette_t=threshold, log_keep=log_keep, skipped=skipped)


def roulette_threshold(previous: Sequence[ChunkResult], kappa: float) -> float:
    """Weight roulette's threshold for the next final chunk: ``kappa`` times the mean
    term ``w c`` of the chunks the estimate would use so far (an estimate of
    P(C and A and B); 0, no roulette, before any collision)."""
    chunks = _counted(previous)
    n = sum(c.n for c in chunks)
    if kappa <= 0 or n == 0:
        return 0.0
    return float(kappa) * sum(float(c.weights[c.collided].sum()) for c in chunks) / n


def _exposure(model: CutInGMM, exposure: Exposure | Mapping[str, Any] | None
              ) -> Exposure | None:
    if exposure is None:
        raw = getattr(model, "exposure_", None)
        return Exposure.from_dict(raw) if raw else None
    if isinstance(exposure, Exposure):
        return exposure
    return Exposure.from_dict(exposure)


def evaluate(model: CutInGMM, runner: Runner, *, constraints: Iterable[Any] | Region | None
             = None, n: int | None = None, rhw: float = DEFAULT_RHW, max_runs: int = 1_000_000,
             seed: int = 0, exposure: Exposure | Mapping[str, Any] | None = None,
             batch_size: int = 2000, progress: ProgressFn | None = None,
             on_chunk: Callable[[ChunkResult], None] | None = None,
             stored: Iterable[ChunkResult | Mapping[str, Any]] = (),
             executor: Executor | None = None, bootstrap: bool = True,
             sut: str | None = None, envelopes: Sequence[str] = DEFAULT_ENVELOPES,
             physical_bounds: bool = True, alpha: float = 0.15, confidence: float = 0.95,
             min_collisions: int = MIN_COLLISIONS, part_size: int = 1024,
             min_fit_hits: int = 2, adapt: str = "ce", rho: float = 0.1,
             ce_min_hits: int = 20, band_step: bool = False,
             tune_shares: bool = False, roulette: float = 0.0,
             final_alpha: float | None = None) -> CampaignResult:
    """Run a campaign: importance-sampled cut-ins driven by ``runner`` until the stop rule.

    Parameters
    ----------
    model : fitted CutInGMM (its bootstrap replicates give the model interval, its
        ``exposure_`` the rates unless ``exposure`` is given)
    runner : ``runner(params (n, 8), seeds (n,) uint64)`` -> outcomes
        (``sampler.campaign.Runner``; ``sut_runner`` for a system under test)
    constraints : constraints or a Region, optional
        Restrict the target to a region A: ``p_collision`` is then per cut-in of A
        (``P(C and A | B) / P(A | B)``, P(A | B) from ``estimate_p_region``), the rates
        count the collisions inside A.
    n : int, optional
        Exactly this many draws (no stop rule); default: stop when the relative half-width
        of the interval is at most ``rhw`` with at least ``min_collisions`` collisions, or
        at ``max_runs`` draws.
    seed : int
        Chunk k draws from ``SeedSequence([seed, k])``; its proposal depends on the chunks
        before it only, so the campaign is deterministic.
    stored : chunks of an earlier run of the same campaign (``ChunkResult`` or its dict):
        replayed in order instead of drawn and simulated (resume after a crash).
    on_chunk : called with each new ``ChunkResult`` (the job stores it)
    executor : concurrent.futures Executor, optional: runs parts of ``part_size`` rows
    progress : ``progress("runs", done, planned)`` after each chunk
    adapt : "ce" (default) or "kernels"
        How later chunks adapt their proposal. "kernels": Student-t kernels on the
        collided runs so far (``min_fit_hits`` of them), every chunk counted. "ce":
        adaptive multi-level cross-entropy on the runner's continuous performance score
        (:func:`performance_score`): pilot chunks fit a normal mixture to the runs below
        the ``rho``-quantile of the score so far, until ``ce_min_hits`` collided runs
        are seen; from then on the mixture is fitted to the collided runs and only those
        chunks (decided before their draws) enter the estimate and the stop rule
        (docs/evaluation.md). A runner without a score (no ``margin`` or ``min_gap``)
        falls back to "kernels" from its second chunk on (the first is the same for
        both), and the result's ``adapt`` says "kernels".
    band_step : bool, default False
        With ``adapt="ce"``: the final stage gives each band part with fewer than 2 d
        collided runs its own cross-entropy step (``ce:<band>-level``) and moves shares
        to the band parts (set and band parts 0.2, band refits 0.3, kernels 0.1, pilot
        levels 0.05), and with the default ``envelopes`` the slow cutter's set is
        ``v_cut_min<1.5`` (``BAND_STEP_ENVELOPES``). Measured better at P near 1e-5 where
        collision families sit on the bands (``acc k2=0.6``: 781 naive runs saved per SUT
        run, 624 with ``v_cut_min<3``, against 168) and
        worse at P near 1e-3 (``acc`` defaults: 18.4 against 46.0) and where the bands
        only slice a failure set (a two-half-space stand-in: about 1.7 times the runs);
        docs/evaluation.md, "When to use ``--band-step``". Off by default for that
        reason; the summary's ``band_step`` says whether it ran.
    tune_shares : bool, default False
        With ``adapt="ce"``: each final-stage chunk sets its parts' shares from the
        collided runs so far, to the shares that minimise the estimated variance of
        the next chunk (``sampler.campaign.proposal.tune_shares``; the model keeps
        ``alpha``, every other part stays within 0.5 - 3 times its fixed share).
    roulette : float, default 0 (off)
        With ``adapt="ce"``, **weight roulette** in the final stage: a draw whose weight
        ``w = p / q`` is below ``t = roulette * P_hat`` (``P_hat`` the estimate of
        P(C and A and B) from the chunks before, fixed before the chunk is drawn) is run
        with probability ``w / t`` and, when run, weighs ``t``; the others are drawn but
        not run (Kahn 1956's Russian roulette). Unbiased for any ``t``; a collision's
        weight can only rise to ``t``, so the variance per draw grows by at most
        ``t P(C)``, while the draws the proposal over-samples (``q`` far above
        ``p / P``) mostly go unrun. Measured at ``acc k2=0.6`` with ``roulette=5``:
        docs/evaluation.md, "Weight roulette". The summary's ``roulette`` and
        ``skipped_runs`` say what it did.
    final_alpha : float, optional (default: ``alpha``)
        With ``adapt="ce"``: the model's defensive share in the final stage only (the
        pilot keeps ``alpha``, so a campaign that never meets a collision keeps the
        no-collision bound of ``alpha``). Every final-stage weight stays below
        ``1 / final_alpha``. With the roulette the model's draws are the runs it cannot
        leave out (their weights are large), so a smaller share there saves runs: the CLI
        and the API run ``ROULETTE_FINAL_ALPHA`` (0.05) with the roulette on;
        docs/evaluation.md, "A smaller defensive share in the final stage".
    """
    model.check_fitted()
    if n is not None and (isinstance(n, bool) or int(n) < 1):
        raise SamplerError(f"n: must be a positive number of runs, got {n!r}", field="n")
    if not (isinstance(rhw, int | float) and 0 < rhw < 10):
        raise SamplerError(f"rhw: must be a relative half-width in (0, 10), got {rhw!r}",
                           field="rhw")
    if int(max_runs) < 1:
        raise SamplerError(f"max_runs: must be >= 1, got {max_runs!r}", field="max_runs")
    if int(batch_size) < 1:
        raise SamplerError(f"batch_size: must be >= 1, got {batch_size!r}",
                           field="batch_size")
    if isinstance(seed, bool) or int(seed) < 0:
        raise SamplerError(f"seed: must be an integer >= 0, got {seed!r}", field="seed")
    if not (isinstance(alpha, int | float) and 0 < alpha <= MAX_ALPHA):
        raise SamplerError(f"alpha: the model's defensive share must be in (0, {MAX_ALPHA:g}], "
                           f"got {alpha!r}", field="alpha")
    if adapt not in ("kernels", "ce"):
        raise SamplerError(f"adapt: must be 'kernels' or 'ce', got {adapt!r}", field="adapt")
    if not (isinstance(rho, int | float) and 0 < rho < 1):
        raise SamplerError(f"rho: must be a quantile in (0, 1), got {rho!r}", field="rho")
    if final_alpha is not None and (isinstance(final_alpha, bool)
                                    or not isinstance(final_alpha, int | float)
                                    or not 0 < final_alpha <= MAX_ALPHA):
        raise SamplerError(f"final_alpha: the model's defensive share in the final stage must "
                           f"be in (0, {MAX_ALPHA:g}], got {final_alpha!r}",
                           field="final_alpha")
    if (isinstance(roulette, bool) or not isinstance(roulette, int | float)
            or not 0 <= roulette <= MAX_ROULETTE):
        raise SamplerError(f"roulette: must be a number in [0, {MAX_ROULETTE:g}] (0: off), "
                           f"got {roulette!r}", field="roulette")
    if int(ce_min_hits) < 1:
        raise SamplerError(f"ce_min_hits: must be >= 1, got {ce_min_hits!r}",
                           field="ce_min_hits")
    seed = int(seed)
    region = _region(model, constraints, physical_bounds)
    if is_dataclass(runner) and hasattr(runner, "lane_width") and runner.lane_width is None:
        runner = replace(runner, lane_width=region.lane_width)  # the campaign's lane width
    exp = _exposure(model, exposure)
    replay = [c if isinstance(c, ChunkResult) else ChunkResult.from_dict(c) for c in stored]
    p_region = None
    if region.constraints:
        p_region = estimate_p_region(model, region, seed=seed)
    planned = int(n) if n is not None else int(max_runs)
    zq = float(norm.ppf(0.5 + confidence / 2))
    pb, cv_b = _p_bounds(model, region)
    envelopes = campaign_envelopes(envelopes, bool(band_step) and adapt == "ce")
    chunks: list[ChunkResult] = []
    ce_fits: dict[int, tuple[Any, float]] = {}
    done = 0
    stop = "max_runs"
    while done < planned:
        k = len(chunks)
        size = min(int(batch_size), planned - done)
        if k < len(replay):
            chunk = replay[k]
            if chunk.index != k or chunk.n != size:
                raise SamplerError(f"stored: chunk {k} does not belong to this campaign "
                                   f"(index {chunk.index}, {chunk.n} runs; expected {size})",
                                   field="stored")
        else:
            chunk = _new_chunk(k, size, model, region, runner, seed, chunks, envelopes,
                               alpha, executor, part_size, min_fit_hits, adapt, float(rho),
                               int(ce_min_hits), ce_fits, bool(band_step),
                               bool(tune_shares), float(roulette),
                               None if final_alpha is None else float(final_alpha))
            if on_chunk is not None:
                on_chunk(chunk)
        chunks.append(chunk)
        done += chunk.n
        if progress is not None:
            progress("runs", done, planned)
        if n is None and (adapt != "ce" or _unscored(chunks)
                          or any(c.counted for c in chunks)):
            est = _estimate(_counted(chunks), "collided", pb, cv_b)
            if est.hits >= min_collisions and est.estimate > 0:
                cv = est.se / est.estimate
                if p_region is not None:
                    lo, hi = float(p_region.ci_low), float(p_region.ci_high)
                    cv = math.sqrt(cv ** 2 + ((math.log(hi) - math.log(lo)) / (2 * zq)) ** 2)
                if zq * cv <= rhw:
                    stop = "rhw"
                    break
    else:
        stop = "n" if n is not None else "max_runs"
    if adapt == "ce" and _unscored(chunks):
        adapt = "kernels"  # the runner gave no score: the kernels' adaptation was used
    return CampaignResult(chunks=chunks, stop_reason=stop, model=model, region=region,
                          seed=seed, sut=sut or getattr(runner, "name", None), exposure=exp,
                          bootstrap=bootstrap, confidence=confidence,
                          rhw_target=None if n is not None else float(rhw), alpha=alpha,
                          final_alpha=None if final_alpha is None else float(final_alpha),
                          p_region=p_region, adapt=adapt,
                          band_step=bool(band_step) and adapt == "ce",
                          roulette=float(roulette) if adapt == "ce" else 0.0)
