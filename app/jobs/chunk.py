"""One chunk of a catalogue: a pure function of (spec, chunk index).

Seeds: chunk i samples with ``chunk_seed(seed, i)``, drawn from
``numpy.random.SeedSequence(seed, spawn_key=...)``; the builder is deterministic, so a
scenario has no seed of its own (its ``seed`` is the catalogue's, its provenance names its
index). So chunk i's content depends only on the catalogue's spec and i: the order in which
chunks run, the executor, and restarts cannot change it. Every vector goes through
``sampler.scenario.record.score_vector`` (the route and the CLI use it too); a vector the builder
refuses is a row with ``error`` set, not a failed chunk.
"""

from __future__ import annotations

import functools
import hashlib
import os
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from app import domain, jsonconv
from app.db import chunkfile
from riskcore import ConcreteScenario
from sampler import Constraint, CutInGMM
from sampler.scenario import ScenarioRecord, score_rows, score_vector

#: seconds between two progress reports of a chunk being computed
PROGRESS_EVERY = 0.25

#: a cut-in that goes through the builder and every criticality kernel (``warm_worker``)
_WARM_VECTOR = {"p_y1": 0.04, "p_t": 2.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
                "p_v0": 25.0, "dv": 2.0, "gap": 12.0}

#: spawn-key prefixes that keep the seed streams apart
_CHUNK_KEY = 1
_REGION_KEY = 3


def _derive(seed: int, *key: int) -> int:
    state = np.random.SeedSequence(seed, spawn_key=key).generate_state(1, dtype=np.uint32)
    return int(state[0]) & 0x7FFFFFFF


def warm_worker(hold: float = 0.0) -> int:
    """Import the chunk machinery in this worker process and load its compiled kernels
    (numba's on-disk cache) by scoring one vector and running the sampler's crossing
    kinematics once, so that the first chunk or request does not pay for it (1-3 s on a
    fresh worker). ``hold``: seconds to stay busy afterwards, so that another idle worker
    takes the next warm-up task. Returns the worker's pid."""
    from sampler.region import crossing_kinematics

    score_vector(_WARM_VECTOR, wagner_scan=True)  # every kernel: the scan's too
    crossing_kinematics(np.array([[_WARM_VECTOR[k] for k in ("p_y1", "p_t", "p_a1", "p_a2",
                                                             "p_a3", "p_v0")]]), 1.875)
    if hold > 0:
        time.sleep(hold)
    return os.getpid()


def chunk_seed(seed: int, index: int) -> int:
    """Sampler seed of chunk ``index`` of a catalogue with seed ``seed`` (31-bit)."""
    return _derive(seed, _CHUNK_KEY, index)


def region_seed(seed: int) -> int:
    """Seed of the catalogue's one P(A) estimate."""
    return _derive(seed, _REGION_KEY)


@dataclass(frozen=True)
class CatalogueSpec:
    """Everything a worker needs to compute any chunk (JSON-able, no DB access)."""

    n: int
    seed: int
    chunk_size: int
    model_json: str
    constraints: tuple[str, ...]
    method: str = "auto"
    score: bool = True
    #: also Wagner's scan (alarm_time, risk_peak, the risks at the crossing)
    wagner_scan: bool = False
    store_trajectories: bool = True
    #: the catalogue's P(A) estimate: each scenario's exposure weight is p_region / n
    p_region: float | None = None
    #: the catalogue's whole P(A) record (with P(B)): every chunk reuses it
    region: dict[str, Any] | None = None
    #: where a worker reports per-scenario progress (``chunkfile.write_progress``); not
    #: part of the catalogue: no chunk's content depends on it
    progress_dir: str | None = None

    @property
    def n_chunks(self) -> int:
        return (self.n + self.chunk_size - 1) // self.chunk_size

    def bounds(self, index: int) -> tuple[int, int]:
        if not 0 <= index < self.n_chunks:
            raise IndexError(f"chunk index {index} outside 0..{self.n_chunks - 1}")
        start = index * self.chunk_size
        return start, min(self.n, start + self.chunk_size)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["constraints"] = list(self.constraints)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CatalogueSpec:
        values = dict(data)
        values["constraints"] = tuple(values.get("constraints", ()))
        return cls(**values)


def scenario_provenance(spec: CatalogueSpec, idx: int) -> dict[str, Any]:
    """What a catalogue scenario records about its origin (no ids: the same seed gives the
    same catalogue whatever store it is in)."""
    return {"catalogue_index": idx, "catalogue_seed": spec.seed,
            "constraints": list(spec.constraints), "sampler": spec.method}


class ChunkStopped(Exception):
    """A chunk given up because its job was cancelled or its catalogue deleted
    (``chunkfile.stop_requested``)."""


@dataclass
class ChunkResult:
    """A computed chunk, ready to be stored in one transaction."""

    index: int
    rows: list[dict[str, Any]]
    blob: bytes | None  # gzip'd JSON lines of the concrete scenarios (deterministic)
    diagnostics: dict[str, Any] = field(default_factory=dict)

    @property
    def sha256(self) -> str | None:
        return None if self.blob is None else hashlib.sha256(self.blob).hexdigest()


def scenario_row(record: ScenarioRecord, chunk_index: int) -> dict[str, Any]:
    """The stored form of a catalogue scenario's record (``ScenarioRow`` columns: one per
    criticality field, ``risk`` = ``risk_peak``, and the scores as JSON for the exports)."""
    scores = record.scores()
    return {
        "idx": record.index,
        "chunk_index": chunk_index,
        "params": record.params,
        "ttc": record.ttc,
        "risk": record.risk_peak,
        "exposure_weight": record.exposure_weight,
        "error": record.error,
        "summary": jsonconv.encode(scores),
        **{("class_" if k == "class" else k): v for k, v in scores.items()},
        # the data support (issue 25): class and the two measures as columns (filtered,
        # ranked, counted in SQL), the rest (nearest row, density percentile, the
        # parameters outside the data's range) as JSON
        "support": record.support,
        "support_distance": record.support_distance,
        "support_excess": record.support_excess,
        "support_detail": None if record.support is None else jsonconv.encode({
            "support_nearest": record.support_nearest, "density_pct": record.density_pct,
            "support_outside": None if record.support_outside is None
            else [o.model_dump() for o in record.support_outside]}),
    }


@functools.lru_cache(maxsize=4)
def _prepared(model_json: str, constraints: tuple[str, ...]) -> tuple[CutInGMM, list[Constraint]]:
    """The model and constraints of a catalogue, parsed once per worker process."""
    return domain.load_model(model_json), domain.parse_constraints(constraints)


def compute_chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
    """Sample, build and (optionally) score chunk ``index`` of the catalogue."""
    start, stop = spec.bounds(index)
    model, constraints = _prepared(spec.model_json, spec.constraints)
    drawn = domain.sample(model, constraints, stop - start, chunk_seed(spec.seed, index),
                          method=spec.method, known_region=spec.region)
    weights = spec.p_region / spec.n if spec.p_region is not None else drawn.weights
    rows: list[dict[str, Any]] = []
    scenarios: list[dict[str, Any] | None] = []
    reported = time.monotonic()
    folder_existed = spec.progress_dir is not None and os.path.isdir(spec.progress_dir)
    if spec.progress_dir is not None and chunkfile.stop_requested(spec.progress_dir,
                                                                  folder_existed):
        raise ChunkStopped(f"chunk {index}: the job was cancelled")
    for record, _ in score_rows(
            drawn.params, start=start, exposure_weights=weights, lane_width=drawn.lane_width,
            seed=spec.seed, provenance=lambda idx: scenario_provenance(spec, idx),
            score=spec.score, include_scenario=spec.store_trajectories,
            wagner_scan=spec.wagner_scan,
            support=None if drawn.sample_set is None else drawn.sample_set.support):
        rows.append(scenario_row(record, index))
        scenarios.append(record.scenario)  # None: the builder refused the vector
        if spec.progress_dir is not None and time.monotonic() - reported >= PROGRESS_EVERY:
            if chunkfile.stop_requested(spec.progress_dir, folder_existed):
                raise ChunkStopped(f"chunk {index}: the job was cancelled")
            chunkfile.write_progress(spec.progress_dir, index, len(rows))
            reported = time.monotonic()
    blob = chunkfile.encode(scenarios) if spec.store_trajectories else None
    diagnostics = jsonconv.encode({"sampler": drawn.diagnostics, "p_region": drawn.p_region})
    return ChunkResult(index=index, rows=rows, blob=blob, diagnostics=diagnostics)


def rebuild_scenario(spec: CatalogueSpec, idx: int, params: Mapping[str, float],
                     lane_width: float) -> ConcreteScenario | None:
    """The concrete scenario of catalogue scenario ``idx`` exactly as its chunk built it
    (the builder is deterministic); None when the builder refuses the vector."""
    _, scenario = score_vector(params, index=idx, lane_width=lane_width, seed=spec.seed,
                               provenance=scenario_provenance(spec, idx), score=False,
                               include_scenario=True)
    return scenario
