"""Every region the docs write, with the time its P(A) estimate takes and its outcome
(issue 27 item 7), under the synchronous budget a request has (``app.budget``).

The regions are the constraints written in backticks in docs/criticality.md and
docs/sampler.md (``ttc<3``, ``btn > 0.4``, ``ttc<3 & btn>0.5`` ...: every text that
parses), plus the ones of the issue (``btn>=1``, ``r157_collision>0.5``,
``r157_impact_speed>0``, ``btn>0.9``, ``btn>0.95``). Each is estimated on the default
model (``app.domain.estimate_region``, seed 0) with a ``Budget`` of ``--budget`` s set as
a request's would be, so the outcome is what ``GET /dashboard/api/models/default/rates``
answers: P(A), refused over the budget (with the time it took to refuse: the budget plus
the longest gap between two progress reports), or refused for another reason. Also the
longest gap between two progress calls (how late a budget can stop the work).

    .venv/bin/python benchmarks/bench_regions.py            # budget 10 s
    .venv/bin/python benchmarks/bench_regions.py --budget 30

The default model is the one fitted in ``--data-dir`` (default: the bench_load cache).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "docs" / "criticality.md", ROOT / "docs" / "sampler.md"]
ISSUE = ["btn>=1", "r157_collision>0.5", "r157_impact_speed>0", "btn>0.9", "btn>0.95"]


def doc_regions() -> list[list[str]]:
    from app import domain
    from app.errors import InvalidInput

    seen: list[list[str]] = []
    for path in DOCS:
        for text in re.findall(r"`([^`\n]+)`", path.read_text()):
            parts = [p.strip() for p in text.split("&")]
            if not all(re.fullmatch(r"[a-z_0-9]+ *(<=|>=|<|>) *-?[0-9.]+(e-?[0-9]+)?", p)
                       for p in parts):
                continue
            try:
                domain.parse_constraints(parts)
            except InvalidInput:
                continue
            key = [p.replace(" ", "") for p in parts]
            if key not in seen:
                seen.append(key)
    for text in ISSUE:
        if [text] not in seen:
            seen.append([text])
    return seen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", type=float, default=10.0)
    ap.add_argument("--data-dir", type=Path,
                    default=Path(tempfile.gettempdir()) / "scengen-bench-load-cache")
    args = ap.parse_args()
    from app import budget, domain
    from app.errors import ServiceError
    from app.services.store import open_context
    from app.settings import Settings

    db = Path(tempfile.mkdtemp(prefix="scengen-regions-")) / "regions.db"
    ctx = open_context(Settings(data_dir=args.data_dir, database_url=f"sqlite:///{db}",
                                local_workers=0, warm_start=False))
    model = ctx.model(ctx.resolve_model_id(None))  # the default model
    rows: list[dict[str, Any]] = []
    for region in doc_regions():
        gaps: list[float] = []
        last = time.monotonic()

        def heard(name: str, done: int, total: int, gaps: list[float] = gaps) -> None:
            nonlocal last
            now = time.monotonic()
            gaps.append(now - last)
            last = now

        token = budget.BUDGET.set(budget.Budget(args.budget, what="estimate"))
        t0 = last = time.monotonic()
        try:
            p = domain.estimate_region(model, domain.parse_constraints(region), 0,
                                       progress=heard)
            outcome = f"P(A) {p['estimate']:.3g}"
        except budget.OverBudget:
            outcome = "refused: over the budget (ask for a catalogue job)"
        except ServiceError as exc:
            outcome = f"refused: {exc.message[:110]}"
        finally:
            budget.BUDGET.reset(token)
        seconds = time.monotonic() - t0
        row = {"region": " & ".join(region), "seconds": round(seconds, 2),
               "outcome": outcome, "longest_gap_s": round(max(gaps, default=seconds), 2)}
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    ctx.close()
    print("| region | s | outcome | longest gap between progress reports, s |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| `{r['region']}` | {r['seconds']} | {r['outcome']} | {r['longest_gap_s']} |")
    within = sum(r["seconds"] <= args.budget + 1 for r in rows)
    print(f"\n{within} of {len(rows)} regions answered or refused within budget + 1 s "
          f"(budget {args.budget:g} s)")


if __name__ == "__main__":
    main()
