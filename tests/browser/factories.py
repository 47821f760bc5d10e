"""Factories shared by the dashboard tests and benchmarks/bench_dashboard.py.

* ``prepare_data_dir``: a data dir whose default model is a quickly fitted one (few
  components, one EM start), so a service starts in seconds instead of fitting the full
  default model. It is written where ``app.context`` looks for its cached default model;
  should that naming change, the service simply fits the full model (slower, same page).
* ``store_synthetic_catalogue``: a finished catalogue of n hand-made, seeded scenario rows
  (no trajectories, no scoring), for the aggregation and payload-size tests and the
  benchmark — the dashboard's cost depends only on the stored rows.
"""

from __future__ import annotations

import math
import socket
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from app import domain, jsonconv
from app.db import repository as repo
from app.db.database import Database
from app.db.models import CatalogueRow, utcnow
from app.services.models import fit_model

#: options of the quick model (sampler.model.gmm.CutInGMM keywords)
QUICK_MODEL_OPTIONS: dict[str, Any] = {"k_range": (1, 3), "n_init": 1, "cv_folds": 2,
                                       "n_report_samples": 2000}
#: Chromium as installed by Debian, and the flags that keep it off the network
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
EVASIONS = ("brake", "steer_left", "steer_right", "steer_left+brake", "none", None)


@lru_cache(maxsize=1)
def _quick_model() -> tuple[str, str]:
    table = domain.embedded_parameter_table()
    fitted = fit_model(table, QUICK_MODEL_OPTIONS)
    return domain.table_hash(table), fitted.model_json


def prepare_data_dir(data_dir: Path) -> Path:
    """Put the quick default model where the service's context caches its default model."""
    data_hash, model_json = _quick_model()
    path = data_dir / "models" / f"default-{data_hash[:16]}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(model_json)
    return data_dir


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def synthetic_rows(n: int, seed: int, chunk_size: int) -> list[dict[str, Any]]:
    """n stored-scenario rows with seeded, plausible values (hand-made, not sampled)."""
    rng = np.random.default_rng(seed)
    p_v0 = rng.normal(25.0, 4.0, n)
    p_t = np.exp(rng.normal(np.log(2.5), 0.2, n))
    side = rng.choice([-1.0, 1.0], n)
    p_y1 = side * 3.8 * np.pi / (2.0 * p_v0 * p_t**2)
    dv = rng.uniform(0.5, 8.0, n)
    ttc = rng.uniform(0.2, 3.0, n)
    gap = ttc * dv
    risk = rng.beta(0.6, 1.5, n)
    min_ttr = np.round(rng.uniform(0.0, 3.0, n), 1)
    no_collision = rng.random(n) < 0.1
    evasion = rng.integers(0, len(EVASIONS) - 1, n)
    crit = synthetic_criticality(n, rng)
    rows = []
    for i in range(n):
        params = {"p_y1": float(p_y1[i]), "p_t": float(p_t[i]), "p_a1": 0.0, "p_a2": 0.0,
                  "p_a3": 0.0, "p_v0": float(p_v0[i]), "dv": float(dv[i]),
                  "gap": float(gap[i])}
        r = 0.0 if no_collision[i] else float(risk[i])
        summary = {"risk": r, "risk_ind": min(1.0, r * 1.1),
                   "min_ttr": "Infinity" if no_collision[i] else float(min_ttr[i]),
                   "min_ttc": float(ttc[i]), "min_wttc": float(ttc[i]) * 0.8,
                   "min_thw": float(gap[i] / (p_v0[i] + dv[i])),
                   "min_ttr_evasion": None if no_collision[i] else EVASIONS[evasion[i]],
                   "step_of_max_risk": 50, "t_of_max_risk": 5.0}
        rows.append({"idx": i, "chunk_index": i // chunk_size, "seed": 1000 + i,
                     "params": params, "ttc": float(ttc[i]), "risk": r,
                     "exposure_weight": 1e-3 / n, "summary": summary,
                     **crit[i]})
    return rows


def synthetic_criticality(n: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    """Criticality columns of n hand-made rows, consistent with the class rules of
    docs/criticality.md: no conflict (btn 0, ttr_true inf), else btn from a gamma law;
    btn >= 1.1 the careful driver collides, some of those are unavoidable; btn = inf
    (contact before the careful driver's braking) for 1 %."""
    decel = 0.774 * 9.81
    out = []
    for _ in range(n):
        u = rng.random()
        conflict = u >= 0.1
        btn = float(rng.gamma(3.0, 0.15)) if conflict else 0.0
        if conflict and u > 0.99:
            btn = math.inf
        r157_hit = conflict and btn >= 1.1
        unavoidable = r157_hit and btn > 1.6
        cls = ("no_conflict" if not conflict else "unavoidable" if unavoidable
               else "unpreventable" if r157_hit else "preventable")
        ttr = (math.inf if not conflict else 0.0 if unavoidable
               else round(float(rng.uniform(0.0, 3.5)), 1))
        rss_hit = conflict and btn >= 0.9
        out.append({
            "t_p": 3.4, "t_cross": 4.6, "ttr_true": ttr,
            "ttr_manoeuvre": None if not conflict else "none" if unavoidable else "brake",
            "a_req": btn * decel, "btn": btn, "class_": cls,
            "none_collision": conflict,
            "none_impact_speed": float(rng.uniform(1.0, 9.0)) if conflict else 0.0,
            "none_min_gap": 0.0 if conflict else 4.0,
            "r157_cc_collision": r157_hit,
            "r157_cc_impact_speed": float(rng.uniform(0.5, 5.0)) if r157_hit else 0.0,
            "r157_cc_min_gap": 0.0 if r157_hit else 2.0,
            "r157_cc_t_brake": 4.15 if conflict else None,
            "rss_collision": rss_hit,
            "rss_impact_speed": float(rng.uniform(0.5, 4.0)) if rss_hit else 0.0,
            "rss_min_gap": 0.0 if rss_hit else 2.5, "rss_t_brake": 3.9 if conflict else None,
            "r_dep_tp": float(min(1.0, rng.beta(0.3, 6.0))), "r_ind_tp": 0.0,
            "r_dep_cross": 0.5, "r_ind_cross": 0.4, "r_dep_tp_r157": 0.0,
            "r_ind_tp_r157": 0.0, "r_dep_cross_r157": 0.2, "r_ind_cross_r157": 0.1,
            "alarm_time": float(rng.uniform(0.2, 2.5)) if conflict else None,
            "risk_peak": 1.0 if conflict else 0.1,
        })
    return out


def store_synthetic_catalogue(db: Database, data_dir: Path, model_id: str, n: int,
                              seed: int = 0, chunk_size: int = 1000,
                              rows: list[dict[str, Any]] | None = None) -> str:
    """A finished catalogue of ``rows`` (default ``synthetic_rows(n, seed, chunk_size)``);
    each chunk gets rejection-sampler diagnostics with acceptance 0.1 · (chunk index + 1)."""
    rows = rows if rows is not None else synthetic_rows(n, seed, chunk_size)
    n_chunks = (n + chunk_size - 1) // chunk_size
    cid = repo.new_id("cat")
    with db.session() as s:
        s.add(CatalogueRow(id=cid, model_id=model_id, status="done", n=n, seed=seed,
                           chunk_size=chunk_size, n_chunks=n_chunks,
                           spec={"constraints": ["ttc<3"], "method": "auto", "score": True,
                                 "store_trajectories": False},
                           p_region={"estimate": 0.001, "ci_low": 0.0009, "ci_high": 0.0011,
                                     "method": "mc"},
                           finished_at=utcnow()))
    for c in range(n_chunks):
        chunk = [dict(r, summary=jsonconv.encode(r["summary"]))
                 for r in rows if r["chunk_index"] == c]
        diag = {"sampler": {"method": "rejection", "acceptance_rate": 0.1 * (c + 1),
                            "ess": float(len(chunk)), "n_draws": 10 * len(chunk)}}
        with db.session() as s:
            repo.store_chunk(s, data_dir, cid, c, chunk, None, None, diag)
    return cid
