"""Run esmini headless on an exported scenario and read its CSV log back (test helper), and
the cut-ins the esmini tests run (test_exports_esmini.py, test_esmini_sut.py).

The binary is ``$SCENGEN_ESMINI`` or ``<repo>/../shared/tools/esmini/bin/esmini``
(``esmini_binary``); None when neither exists, so that the tests skip.
"""

from __future__ import annotations

import csv
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from riskcore.scenario import ConcreteScenario
from sampler.scenario.builder import build_scenario

REPO = Path(__file__).resolve().parents[2]
DEFAULT_ESMINI = REPO.parent / "shared" / "tools" / "esmini" / "bin" / "esmini"
ENV_VAR = "SCENGEN_ESMINI"

#: cut-ins from the left and the right, closing (collisions) and opening, highway speeds
CUTIN_PARAMS = [
    {"p_y1": -0.05, "p_t": 2.0, "p_a1": 0.5, "p_a2": 0.25, "p_a3": 1.0, "p_v0": 25.0,
     "dv": 4.0, "gap": 2.0},
    {"p_y1": 0.08, "p_t": 1.5, "p_a1": -1.0, "p_a2": -0.5, "p_a3": 2.0, "p_v0": 20.0,
     "dv": 3.0, "gap": 4.0},
    {"p_y1": 0.05, "p_t": 1.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0, "p_v0": 31.0,
     "dv": -1.0, "gap": 20.0},
    {"p_y1": -0.04, "p_t": 2.5, "p_a1": 1.0, "p_a2": -3.0, "p_a3": 1.0, "p_v0": 33.0,
     "dv": 6.0, "gap": 8.0},
]


def cutins(params: list[dict[str, float]]) -> list[ConcreteScenario]:
    """The scenarios of ``params`` (scenario i built with seed i)."""
    return [build_scenario(p, seed=i) for i, p in enumerate(params)]


def esmini_binary() -> Path | None:
    """The esmini executable to use, or None when there is none."""
    value = os.environ.get(ENV_VAR)
    path = Path(value) if value else DEFAULT_ESMINI
    return path if path.is_file() and os.access(path, os.X_OK) else None


@dataclass
class EntityLog:
    """One entity's logged states; box centre = position + R(h) (bb_x, bb_y)."""

    t: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    h: list[float] = field(default_factory=list)
    bb_x: list[float] = field(default_factory=list)
    bb_y: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    collisions: list[str] = field(default_factory=list)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        h = np.asarray(self.h)
        bx, by = np.asarray(self.bb_x), np.asarray(self.bb_y)
        cx = np.asarray(self.x) + bx * np.cos(h) - by * np.sin(h)
        cy = np.asarray(self.y) + bx * np.sin(h) + by * np.cos(h)
        return cx, cy


def read_csv_log(path: Path) -> dict[str, EntityLog]:
    """esmini's ``--csv_logger`` file as entity name -> EntityLog."""
    logs: dict[str, EntityLog] = {}
    with path.open(encoding="utf-8", errors="replace") as fh:
        lines = fh.read().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("Index"))
    header = [c.strip() for c in lines[head].split(",")]
    # columns of entity #1; later entities repeat the same block
    first = [c for c in header if c.startswith("#1 ")]
    block = len(first)
    names = [c[3:] for c in first]
    start = header.index(first[0])
    for row in csv.reader(lines[head + 1:]):
        if not row or not row[0].strip():
            continue
        cells = [c.strip() for c in row]
        t = float(cells[1])
        k = start
        while k + block <= len(cells) and cells[k]:
            values = dict(zip(names, cells[k:k + block], strict=True))
            log = logs.setdefault(values["Entity_Name [-]"], EntityLog())
            log.t.append(t)
            log.x.append(float(values["World_Position_X [m]"]))
            log.y.append(float(values["World_Position_Y [m]"]))
            log.h.append(float(values["World_Heading_Angle [rad]"]))
            log.bb_x.append(float(values["bb_x [m]"]))
            log.bb_y.append(float(values["bb_y [m]"]))
            log.speed.append(float(values["Current_Speed [m/s]"]))
            log.collisions.append(values["collision_ids"])
            k += block
    return logs


def run_esmini(binary: Path, xosc: Path, out_csv: Path, *, step: float,
               extra: tuple[str, ...] = (), timeout: float = 120.0) -> dict[str, EntityLog]:
    """Run ``xosc`` headless with a fixed time step, collision detection and the CSV log
    (default trajectory filter and interpolation settings: the export must not need
    special options). Returns the parsed log."""
    cmd = [str(binary), "--headless", "--osc", str(xosc), "--fixed_timestep", repr(step),
           "--collision", "--csv_logger", str(out_csv), "--disable_stdout",
           "--logfile_path", str(out_csv.with_suffix(".log")), *extra]
    proc = subprocess.run(cmd, cwd=xosc.parent, capture_output=True, text=True,
                          timeout=timeout, check=False)
    if not out_csv.exists():  # a --param_dist run names its files <stem>_<i+1>_of_<n>
        found = sorted(out_csv.parent.glob(f"{out_csv.stem}_*_of_*{out_csv.suffix}"))
        out_csv = found[0] if len(found) == 1 else out_csv
    if proc.returncode != 0 or not out_csv.exists():
        log = out_csv.with_suffix(".log")
        text = log.read_text(errors="replace")[-2000:] if log.exists() else ""
        raise RuntimeError(f"esmini failed ({proc.returncode}) on {xosc}: {proc.stderr}\n{text}")
    return read_csv_log(out_csv)


#: esmini's own controllers that can stand in for a system under test on the ego:
#: label -> (controller type, properties); ACC with its default 1.5 s time gap, the ALKS
#: R157 models of ControllerALKS_R157SM.cpp
ESMINI_SUTS: dict[str, tuple[str, dict[str, str]]] = {
    "ACC": ("ACCController", {}),
    **{f"R157 {model}": ("ALKS_R157SM_Controller", {"model": model})
       for model in ("ReferenceDriver", "Regulation", "RSS", "FSM")},
}


def with_controller(xosc: bytes, controller: str, properties: dict[str, str] | None = None,
                    entity: str = "ego") -> bytes:
    """A copy of an OpenSCENARIO document whose ``entity`` is driven (longitudinally) by
    esmini's ``controller``: an ``ObjectController`` in its entity definition with the
    ``esminiController`` property, activated in ``Init``."""
    doc = etree.fromstring(xosc)
    [obj] = doc.xpath(f"/OpenSCENARIO/Entities/ScenarioObject[@name='{entity}']")
    ctrl = etree.SubElement(etree.SubElement(obj, "ObjectController"), "Controller",
                            name=controller)
    props = etree.SubElement(ctrl, "Properties")
    for name, value in {"esminiController": controller, **(properties or {})}.items():
        etree.SubElement(props, "Property", name=name, value=value)
    [private] = doc.xpath(f"/OpenSCENARIO/Storyboard/Init/Actions/Private[@entityRef='{entity}']")
    action = etree.SubElement(etree.SubElement(private, "PrivateAction"), "ControllerAction")
    etree.SubElement(action, "ActivateControllerAction", longitudinal="true", lateral="false")
    out: bytes = etree.tostring(doc, xml_declaration=True, encoding="UTF-8")
    return out
