"""When a campaign's figures are not to be trusted: one rule, over the summary's figures
(``CampaignResult.summary()``), shared by the CLI, the HTTP API and the dashboard
(docs/evaluation.md, "Warnings").

:func:`assess` is pure: it reads only the summary's own numbers (``collisions``, ``ess``,
``runs``, ``p_collision``'s ``upper_bound`` and ``rhw``, ``stop_reason``, ``rhw_target``,
``adapt``, ``pilot_runs``, ``confidence``), so a summary stored before these fields existed
gets the same verdict when it is read again (:func:`with_verdict`).

The rule:

* ``no_collision``: no collided run among the counted draws; the summary gives only an
  upper bound (the widened rule of three), no estimate;
* ``few_collisions``: at least one but fewer than :data:`MIN_COLLISIONS` collisions; the
  log-normal interval and ``acceleration`` rest on a handful of weights;
* ``low_ess``: at least one collision and Kish's effective number of collisions below
  :data:`MIN_ESS` (or undefined): a few heavy weights carry the estimate;
* ``max_runs``: the stop rule was asked for (``rhw_target`` set) but the campaign ended at
  ``max_runs`` draws before reaching it;
* ``ce_no_final_stage``: a cross-entropy campaign (``adapt="ce"``) that ended before any
  final chunk, so every chunk, the pilot ones included, makes the estimate
  (``pilot_runs`` 0; ``sampler.campaign.evaluate._counted``).

The first three are about the interval itself; the dashboard greys the interval for
``few_collisions`` and ``low_ess`` (:func:`interval_reasons`) and shows the upper bound
instead for ``no_collision``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["INTERVAL_CODES", "MIN_COLLISIONS", "MIN_ESS", "Finding", "assess",
           "interval_reasons", "verdict", "warnings", "with_verdict"]

#: below this many collisions (and at least one) the interval is not trustworthy
MIN_COLLISIONS = 10
#: below this effective number of collisions the interval is not trustworthy
MIN_ESS = 10.0
#: the findings about the interval itself given at least one collision (the dashboard's
#: "unreliable" flag)
INTERVAL_CODES = ("few_collisions", "low_ess")


@dataclass(frozen=True)
class Finding:
    """One reason not to trust a campaign's figures: ``code`` (stable, for programs),
    ``text`` (one plain-English sentence for the reader) and ``short`` (a few words, for
    a table cell)."""

    code: str
    text: str
    short: str


def _int(v: Any) -> int | None:
    if isinstance(v, bool) or v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return int(f) if math.isfinite(f) else None


def _float(v: Any) -> float | None:
    if isinstance(v, bool) or v is None:
        return None
    try:
        f = float(v)  # also the JSON convention's "nan" / "inf" strings
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _plural(k: int, word: str) -> str:
    return f"{k} {word}{'' if k == 1 else 's'}"


def assess(summary: Mapping[str, Any]) -> list[Finding]:
    """The reasons not to trust the campaign whose summary this is, in a fixed order
    (empty: reliable). Missing fields (an older summary) are read as "not known" and
    raise no finding of their own."""
    out: list[Finding] = []
    k = _int(summary.get("collisions"))
    runs = _int(summary.get("runs"))
    pc = summary.get("p_collision")
    p_col: Mapping[str, Any] = pc if isinstance(pc, Mapping) else {}
    conf = _float(summary.get("confidence")) or 0.95
    level = f"{100 * conf:g} %"
    if k == 0:
        ub = _float(p_col.get("upper_bound"))
        bound = (f"only the {level} upper bound {ub:.3g} per cut-in" if ub is not None
                 else "no upper bound either")
        out.append(Finding(
            "no_collision",
            f"no collision in {'the' if runs is None else runs} draws: P(collision) is "
            f"not estimated, {bound} is given; run more draws to get an estimate",
            "no collision"))
    elif k is not None:
        if k < MIN_COLLISIONS:
            out.append(Finding(
                "few_collisions",
                f"only {_plural(k, 'collision')} (fewer than {MIN_COLLISIONS}): the "
                "interval and the acceleration are not trustworthy; run more draws (a "
                "larger n or the rhw stop rule)",
                f"only {_plural(k, 'collision')}"))
        ess = _float(summary.get("ess"))
        if ess is None or ess < MIN_ESS:
            shown = "undefined" if ess is None else f"{ess:.3g}"
            out.append(Finding(
                "low_ess",
                f"effective sample size (ESS) {shown}, below {MIN_ESS:g}: a few heavy "
                "weights carry the estimate, so its interval is not trustworthy; run more "
                "draws",
                f"ESS {shown}"))
    target = _float(summary.get("rhw_target"))
    if summary.get("stop_reason") == "max_runs" and target is not None:
        rhw = _float(p_col.get("rhw"))
        reached = ("no relative half-width (no collision)" if rhw is None
                   else f"relative half-width {rhw:.2g}")
        out.append(Finding(
            "max_runs",
            f"stopped at max_runs ({'the limit of' if runs is None else runs} draws) "
            f"before the stop rule was met (relative half-width at most {target:g} and "
            f"enough collisions): {reached}; raise max_runs",
            "stopped at max_runs"))
    pilot = _int(summary.get("pilot_runs"))
    chunks = _int(summary.get("chunks"))
    # without any collision the no_collision finding says it all; a campaign of one chunk
    # drew only the defensive mixture, as a kernels campaign's first chunk does
    if (summary.get("adapt") == "ce" and pilot == 0 and (runs or 0) > 0 and k != 0
            and (chunks is None or chunks > 1)):
        out.append(Finding(
            "ce_no_final_stage",
            "adapt=ce: the campaign ended before its final stage (no chunk was fitted on "
            "enough collided runs), so every chunk, the pilot ones included, makes the "
            "estimate; give it more draws",
            "no final cross-entropy stage"))
    return out


def warnings(summary: Mapping[str, Any]) -> list[str]:
    """The plain-English sentences of :func:`assess` (empty: reliable)."""
    return [f.text for f in assess(summary)]


def verdict(summary: Mapping[str, Any]) -> dict[str, Any]:
    """``{"warnings": warnings(summary), "reliable": no warning}``: the two fields the
    summary carries."""
    found = warnings(summary)
    return {"warnings": found, "reliable": not found}


def with_verdict(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The summary with ``warnings`` and ``reliable`` set (again) from its own figures: a
    new summary, or one stored before these fields existed."""
    return {**summary, **verdict(summary)}


def interval_reasons(collisions: Any, ess: Any) -> list[str]:
    """The short reasons (``Finding.short``) why the interval of a campaign with
    ``collisions`` collided runs and effective sample size ``ess`` is not to be trusted:
    the findings ``few_collisions`` and ``low_ess`` of :func:`assess` (none without any
    collision: the upper bound is shown then)."""
    return [f.short for f in assess({"collisions": collisions or 0, "ess": ess})
            if f.code in INTERVAL_CODES]
