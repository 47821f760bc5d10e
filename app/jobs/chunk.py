"""One chunk of a catalogue: a pure function of (spec, chunk index).

Seeds: chunk i samples with ``chunk_seed(seed, i)`` and scenario j (global index) is built
with ``scenario_seed(seed, j)``, both drawn from ``numpy.random.SeedSequence(seed,
spawn_key=...)``. So chunk i's content depends only on the catalogue's spec and i: the
order in which chunks run, the executor, and restarts cannot change it.
"""

from __future__ import annotations

import gzip
import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from app import domain

#: spawn-key prefixes that keep the seed streams apart
_CHUNK_KEY = 1
_SCENARIO_KEY = 2
_REGION_KEY = 3


def _derive(seed: int, *key: int) -> int:
    state = np.random.SeedSequence(seed, spawn_key=key).generate_state(1, dtype=np.uint32)
    return int(state[0]) & 0x7FFFFFFF


def chunk_seed(seed: int, index: int) -> int:
    """Sampler seed of chunk ``index`` of a catalogue with seed ``seed`` (31-bit)."""
    return _derive(seed, _CHUNK_KEY, index)


def scenario_seed(seed: int, idx: int) -> int:
    """Builder seed of scenario ``idx`` (0 .. n-1) of a catalogue (31-bit)."""
    return _derive(seed, _SCENARIO_KEY, idx)


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
    store_trajectories: bool = True
    #: the catalogue's P(A) estimate: each scenario's exposure weight is p_region / n
    p_region: float | None = None

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


def compute_chunk(spec: CatalogueSpec, index: int) -> ChunkResult:
    """Sample, build and (optionally) score chunk ``index`` of the catalogue."""
    start, stop = spec.bounds(index)
    model = domain.load_model(spec.model_json)
    constraints = domain.parse_constraints(spec.constraints)
    drawn = domain.sample(model, constraints, stop - start, chunk_seed(spec.seed, index),
                          method=spec.method)
    names = list(domain.PARAM_NAMES)
    table = drawn.params[names].to_numpy(dtype=np.float64)
    rows: list[dict[str, Any]] = []
    lines: list[str] = []
    for k in range(stop - start):
        idx = start + k
        params = {name: float(table[k, j]) for j, name in enumerate(names)}
        seed = scenario_seed(spec.seed, idx)
        scenario = domain.build_scenario(params, seed, drawn.lane_width,
                                         provenance=scenario_provenance(spec, idx))
        summary = domain.score_scenario(scenario) if spec.score else {}
        risk = summary.get("risk")
        rows.append({
            "idx": idx,
            "chunk_index": index,
            "seed": seed,
            "params": params,
            "ttc": domain.ttc_of(params),
            "risk": None if risk is None else float(risk),
            "exposure_weight": (spec.p_region / spec.n if spec.p_region is not None
                                else float(drawn.weights[k])),
            "summary": domain.encode_floats(summary),
        })
        if spec.store_trajectories:
            lines.append(json.dumps(scenario.to_dict(), separators=(",", ":")))
    blob = None
    if spec.store_trajectories:
        blob = gzip.compress(("\n".join(lines) + "\n").encode(), compresslevel=6, mtime=0)
    diagnostics = domain.encode_floats({"sampler": drawn.diagnostics, "p_region": drawn.p_region})
    return ChunkResult(index=index, rows=rows, blob=blob, diagnostics=diagnostics)
