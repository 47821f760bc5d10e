"""Write the converted TNO data with its licence and provenance (``scengen data convert-tno``)."""

from __future__ import annotations

import shutil
from pathlib import Path

from datasets.egocentric import write_egocentric
from datasets.errors import FormatError
from datasets.tno import EGO_SIZE, TARGET_SIZE, PlausibilityLimits, TnoConversion, convert_tno

__all__ = ["PROVENANCE_TEXT", "write_tno_package"]

PROVENANCE_TEXT = """\
# Provenance of the embedded cut-in data

- Source: public repository ErwindeGelder/ScenarioRiskQuantification, file
  `data/scenarios/cut-in.json`, commit 627aa1e (copy in `../shared/data/tno-cutin/`).
- Paper: E. de Gelder, H. Elrofai, A. Khabbaz Saberi, J.-P. Paardekooper, O. Op den Camp,
  B. De Schutter, "Risk Quantification for Automated Driving Systems in Driving Scenarios",
  IEEE Access 9:168953-168970, 2021, doi 10.1109/ACCESS.2021.3136585.
- Licence: MIT, copyright (c) 2021 ErwindeGelder; the notice is in `LICENSE` beside this
  file and must stay with any copy of this data.
- Content: 297 real highway cut-ins measured by TNO's instrumented car (on-board sensors,
  43 drives, 2017-05-31 to 2017-06-08).

## What the conversion did (`scengen data convert-tno`, module `datasets.tno`)
- Evaluated the B-splines of each scenario's activities (scipy `splev`, normalised time)
  on a {rate:g} Hz grid from {pre:g} s before to {post:g} s after the target's lane change,
  cut to where the target's longitudinal data and the ego's speed both exist.
- Target speed = `vabs`; `target_dy` = the lane-change `dy` (held at its end values
  outside the lane change); `target_dx = dx + (ego_length + target_length) / 2`, reading
  TNO's `dx` as bumper-to-bumper (front of the ego to the rear of the target).
- Sizes are not in the source: assumed ego {el:g} m x {ew:g} m, target {tl:g} m x {tw:g} m.
  The lane width is not in the source: assumed {lw:g} m (`lane_width` column).
- The ego's "lane keeping" spline holds values that look like a speed, not a lateral
  position, so it is not used: `ego_y` is NaN (the ego keeps its lane centre).
- Left out as implausible ({n_rej} of {n_all}): target or ego speed below {vmin:g} m/s,
  lateral speed above {latmax:g} m/s, lane change shorter than {tmin:g} s, lateral
  displacement below {dmin:g} m, target not moving towards the ego's lane, not crossing
  the lane marking at |dy| = lane width / 2, target not ahead of the ego. Each event left
  out is listed below with its reason. Event ids are `tno-NNN`, NNN the 1-based position
  of the scenario in the source file.

## Events left out
{rejected}
"""


def write_tno_package(
    source: Path, output: Path, *, rate: float = 10.0,
    limits: PlausibilityLimits | None = None,
) -> TnoConversion:
    """Convert ``source`` and write ``output`` plus ``LICENSE`` and ``PROVENANCE.md`` beside it.

    The licence is copied from the ``LICENSE`` file next to ``source``; without it nothing
    is written (the MIT terms require the notice to travel with the data).
    """
    licence = source.parent / "LICENSE"
    if not licence.is_file():
        raise FormatError(f"{licence}: missing; the MIT notice must ship with the data")
    limits = limits or PlausibilityLimits()
    pre = post = 3.0
    conv = convert_tno(source, rate=rate, pre=pre, post=post, limits=limits)
    write_egocentric(conv.frame, output)
    shutil.copyfile(licence, output.parent / "LICENSE")
    rejected = "\n".join(f"- {eid}: {reason}" for eid, reason in conv.rejected) or "- none"
    (output.parent / "PROVENANCE.md").write_text(PROVENANCE_TEXT.format(
        rate=rate, pre=pre, post=post, el=EGO_SIZE[0], ew=EGO_SIZE[1], tl=TARGET_SIZE[0],
        tw=TARGET_SIZE[1], lw=limits.lane_width, n_rej=len(conv.rejected),
        n_all=conv.n_scenarios, vmin=limits.min_speed, latmax=limits.max_lat_speed,
        tmin=limits.min_duration, dmin=limits.min_displacement, rejected=rejected,
    ))
    return conv
