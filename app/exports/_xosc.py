"""OpenSCENARIO 1.2 export: one zip with every scenario as a ``.xosc``, the catalogue as
one logical scenario, one road, an index. The documents are built in ``_osc``.

Zip layout (entries sorted by name, fixed timestamps, so the same catalogue gives the
same bytes)::

    catalogs/scengen_cutter_trajectories.xosc   Trajectory catalogue of the logical scenario
    catalogue.csv                 the CSV export's rows with a leading ``file`` column
    cutin_distribution.xosc       deterministic ParameterValueDistribution, one set a scenario
    cutin_logical.xosc            the parameterised test-mode scenario
    cutin_weights.csv             permutation, index, file, exposure weight
    manifest.json                 the manifest plus an ``export`` section (see below)
    road.xodr                     OpenDRIVE 1.7: one straight one-way multi-lane road
    scenario_0000000.xosc         one OpenSCENARIO 1.2 file per scenario, in ``mode``
    ...

Coordinates: scengen's road frame is the OpenSCENARIO/OpenDRIVE world frame; the ego
lane's centre line is y = 0. Positions are rear axles (see ``_osc``). Road: the reference
line is the road's left edge; all lanes are right lanes (ids -1, -2, ...) driving in +x,
``lane_width`` wide (``params["lane_width"]``, else ``provenance["lane_width"]``, else
``DEFAULT_LANE_WIDTH``; all scenarios of a catalogue must agree); at least one lane left
and one right of the ego lane, more as the vehicles' centres need; the road spans every
vehicle's x range plus ``ROAD_MARGIN`` m on both sides, in ``test`` mode also whatever
a vehicle can reach until the run's time limit (``_osc.reach_of_test_run``).

Validation: each ``.xosc`` against ``OpenSCENARIO_1_2.xsd`` and the ``.xodr`` against
``opendrive_17_core.xsd``, both shipped with ``scenariogeneration``; any error fails the
export with the first schema messages. Details in docs/exports.md.
"""

from __future__ import annotations

import csv
import datetime as dt
import functools
import importlib.metadata
import math
import os
import threading
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree
from scenariogeneration import xodr

from app.exports import _osc as osc
from app.exports._common import ExportError, Row, dumps
from app.exports._tabular import CsvRowWriter
from datasets import DEFAULT_LANE_WIDTH, PARAM_NAMES
from riskcore import ConcreteScenario

Item = tuple[int, ConcreteScenario, Mapping[str, Any], Row]

OSC_XSD = "OpenSCENARIO_1_2.xsd"
ODR_XSD = "opendrive_17_core.xsd"
ROAD_FILE = "road.xodr"
MANIFEST_FILE = "manifest.json"
INDEX_FILE = "catalogue.csv"
#: digits of the catalogue index in scenario file names (zero-padded, so names sort)
INDEX_DIGITS = 7
#: metres of road before the first and after the last vehicle position
ROAD_MARGIN = 50.0
#: the catalogue as one logical scenario (see docs/exports.md)
LOGICAL_FILE = "cutin_logical.xosc"
DISTRIBUTION_FILE = "cutin_distribution.xosc"
WEIGHTS_FILE = "cutin_weights.csv"
# esmini looks the catalogue up as <directory>/<catalogName>.xosc
CATALOG_FILE = f"{osc.CATALOG_DIR}/{osc.TRAJECTORY_CATALOG}.xosc"
#: header date when the manifest carries no ``created_at`` (keeps exports deterministic)
DEFAULT_DATE = dt.datetime(1970, 1, 1)
#: zip entry timestamp (the earliest a zip can hold) and permissions
ZIP_DATE = (1980, 1, 1, 0, 0, 0)
ZIP_MODE = 0o644

# scenariogeneration keeps the OpenSCENARIO version in a class attribute shared by every
# object, and the lxml schema objects are shared too; building, serialising and validating
# happen under this lock so that concurrent exports in threads cannot interfere.
_LOCK = threading.RLock()


def schema_path(name: str) -> Path:
    """Where the installed ``scenariogeneration`` distribution keeps the XSD ``name``."""
    try:
        files = importlib.metadata.files("scenariogeneration") or []
    except importlib.metadata.PackageNotFoundError:
        raise ExportError("the scenariogeneration package is not installed") from None
    for file in files:
        if file.name == name:
            return Path(str(file.locate()))
    raise ExportError(f"{name} not found in the scenariogeneration installation")


@functools.cache
def _schema(name: str) -> etree.XMLSchema:
    path = schema_path(name)
    try:
        return etree.XMLSchema(etree.parse(str(path)))
    except (OSError, etree.XMLSchemaParseError, etree.XMLSyntaxError) as exc:
        raise ExportError(f"cannot load the schema {path}: {exc}") from None


def _to_lxml(element: ET.Element) -> etree._Element:
    """The same tree as lxml elements, built node by node (ElementTree's pure-Python
    serialiser was most of the export time)."""
    # scenariogeneration writes namespace declarations as plain attributes
    # ("xmlns:xsi", "xsi:noNamespaceSchemaLocation"); lxml wants them as an nsmap and
    # {namespace}name attributes.
    nsmap = {k.split(":", 1)[1]: v for k, v in element.attrib.items()
             if k.startswith("xmlns:")}
    attrib = {}
    for key, value in element.attrib.items():
        if key.startswith("xmlns:"):
            continue
        prefix, sep, local = key.partition(":")
        attrib[f"{{{nsmap[prefix]}}}{local}" if sep and prefix in nsmap else key] = value
    root = etree.Element(element.tag, attrib, nsmap=nsmap or None)
    root.text = element.text
    stack = [(element, root)]
    while stack:
        source, target = stack.pop()
        for child in source:
            node = etree.SubElement(target, child.tag, dict(child.attrib))
            node.text = child.text
            node.tail = child.tail
            stack.append((child, node))
    return root


def _validated_bytes(element: ET.Element, schema_name: str, what: str) -> bytes:
    """Serialise, validate against the XSD, return pretty-printed UTF-8 with declaration."""
    return _validated_tree(_to_lxml(element), schema_name, what)


def _validated_tree(doc: etree._Element, schema_name: str, what: str) -> bytes:
    """Validate an lxml tree against the XSD; pretty-printed UTF-8 with declaration."""
    schema = _schema(schema_name)
    with _LOCK:
        valid = schema.validate(doc)
        errors = "; ".join(
            f"line {e.line}: {e.message}" for e in list(schema.error_log)[:3]
        )
    if not valid:
        raise ExportError(f"{what} does not validate against {schema_name}: {errors}")
    out: bytes = etree.tostring(doc, pretty_print=True, xml_declaration=True,
                                encoding="UTF-8")
    return out


def _creation_date(manifest: Mapping[str, Any]) -> dt.datetime:
    value = manifest.get("created_at")
    if value is None:
        return DEFAULT_DATE
    if not isinstance(value, str):
        raise ExportError(f"manifest.created_at: expected an ISO 8601 string, got {value!r}")
    try:
        return dt.datetime.fromisoformat(value)
    except ValueError:
        raise ExportError(
            f"manifest.created_at: {value!r} is not an ISO 8601 date-time"
        ) from None


def _num(value: float) -> str:
    return repr(float(value))


def _properties(index: int, scenario: ConcreteScenario, row: Row, mode: str) -> dict[str, str]:
    props = {"scengen.index": str(index), "scengen.mode": mode,
             "scengen.t0": _num(scenario.t[0])}
    if row.get("scenario_id") is not None:
        props["scengen.scenario_id"] = str(row["scenario_id"])
    if scenario.seed is not None:
        props["scengen.seed"] = str(scenario.seed)
    for name, value in scenario.params.items():
        props[f"scengen.param.{name}"] = _num(value)
    return props


def check_mode(mode: str) -> str:
    if mode not in osc.MODES:
        raise ExportError(f"mode: unknown OpenSCENARIO mode {mode!r}; choose one of "
                          f"{', '.join(osc.MODES)}")
    return mode


def scenario_xosc(
    scenario: ConcreteScenario,
    *,
    index: int = 0,
    row: Row | None = None,
    mode: str = osc.DEFAULT_MODE,
    road_file: str = ROAD_FILE,
    date: dt.datetime = DEFAULT_DATE,
) -> bytes:
    """One scenario as a validated OpenSCENARIO 1.2 document (UTF-8 bytes) in ``mode``."""
    check_mode(mode)
    if not scenario.objects:
        raise ExportError("the scenario has no objects besides the ego")
    row = row or {}
    root = osc.scenario_document(
        scenario, mode=mode, description=f"scengen scenario {index} ({mode})", date=date,
        properties=_properties(index, scenario, row, mode),
        declarations=osc.scenario_declarations(scenario, row), road_file=road_file,
    )
    return _validated_tree(root, OSC_XSD, f"scenario {index} (.xosc)")


@dataclass
class RoadExtent:
    """What the shared road has to cover (m), grown scenario by scenario."""

    lane_width: float
    x_min: float = math.inf
    x_max: float = -math.inf
    y_min: float = 0.0
    y_max: float = 0.0

    def add(self, scenario: ConcreteScenario) -> None:
        for track in (scenario.ego, *scenario.objects):
            half = track.length / 2
            self.x_min = min(self.x_min, float(np.min(track.x)) - half)
            self.x_max = max(self.x_max, float(np.max(track.x)) + half)
            self.y_min = min(self.y_min, float(np.min(track.y)))
            self.y_max = max(self.y_max, float(np.max(track.y)))

    def reach(self, x_lo: float, x_hi: float) -> None:
        """Also cover the x interval [x_lo, x_hi] (m)."""
        self.x_min = min(self.x_min, x_lo)
        self.x_max = max(self.x_max, x_hi)

    def lanes(self) -> tuple[int, int]:
        """Lanes left and right of the ego lane (>= 1 each) holding every vehicle centre."""
        w = self.lane_width
        n_left = max(1, math.floor(self.y_max / w + 0.5))
        n_right = max(1, math.floor(-self.y_min / w + 0.5))
        return n_left, n_right

    def x_range(self) -> tuple[float, float]:
        return (float(math.floor(self.x_min - ROAD_MARGIN)),
                float(math.ceil(self.x_max + ROAD_MARGIN)))


def road_xodr(extent: RoadExtent) -> bytes:
    """The shared straight road as a validated OpenDRIVE 1.7 document (UTF-8 bytes)."""
    n_left, n_right = extent.lanes()
    w = extent.lane_width
    x_start, x_end = extent.x_range()
    n_lanes = n_left + 1 + n_right
    y_ref = (n_left + 0.5) * w
    with _LOCK:  # the schema objects are shared; validate one document at a time
        road = xodr.create_road(xodr.Line(x_end - x_start), id=1, left_lanes=0,
                                right_lanes=n_lanes, lane_width=w)
        road.planview.set_start_point(x_start, y_ref, 0.0)
        odr = xodr.OpenDrive("scengen straight road", revMajor="1", revMinor="7")
        odr.add_road(road)
        odr.adjust_roads_and_lanes()
        element = odr.get_element()
        header = element.find("header")
        if header is None:  # pragma: no cover - scenariogeneration always writes one
            raise ExportError("scenariogeneration wrote an OpenDRIVE file without a header")
        header.attrib.pop("date", None)  # wall-clock time: not deterministic
        header.set("north", _num(y_ref))
        header.set("south", _num(y_ref - n_lanes * w))
        header.set("west", _num(x_start))
        header.set("east", _num(x_end))
        return _validated_bytes(element, ODR_XSD, f"the road ({ROAD_FILE})")


def _lane_width(scenario: ConcreteScenario, index: int) -> float:
    """``params["lane_width"]``, else ``provenance["lane_width"]`` (where the sampler's
    builder records it), else ``DEFAULT_LANE_WIDTH`` (m)."""
    if "lane_width" in scenario.params:
        value: Any = scenario.params["lane_width"]
        where = "params.lane_width"
    elif "lane_width" in scenario.provenance:
        value = scenario.provenance["lane_width"]
        where = "provenance.lane_width"
    else:
        return DEFAULT_LANE_WIDTH
    if (isinstance(value, bool) or not isinstance(value, int | float)
            or not math.isfinite(value) or value <= 0):
        raise ExportError(f"item {index}: {where} must be a number > 0 m, got {value!r}")
    return float(value)


def _zinfo(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.create_system = 3  # unix, so that the permission bits mean the same everywhere
    info.external_attr = ZIP_MODE << 16
    return info


def scenario_file_name(index: int) -> str:
    return f"scenario_{index:0{INDEX_DIGITS}d}.xosc"


class LogicalCatalogue:
    """The catalogue as one logical scenario, written alongside the per-scenario files.

    ``LOGICAL_FILE``: the test-mode scenario with every per-scenario value a parameter;
    ``DISTRIBUTION_FILE``: a deterministic ``ParameterValueDistribution`` with one
    ``ParameterValueSet`` per scenario, in catalogue order (permutation i = i-th scenario);
    ``CATALOG_FILE``: the cutters' trajectories, one catalogue entry per scenario, picked by
    the ``cutter_trajectory`` parameter; ``WEIGHTS_FILE``: permutation, catalogue index,
    per-scenario file and exposure weight. Only catalogues of single-cutter scenarios with
    every cut-in parameter have one; ``reason`` says why there is none.
    """

    def __init__(self, scratch: Path, date: dt.datetime) -> None:
        self.date = date
        self.reason: str | None = None
        self.count = 0
        self.names: list[osc.Declaration] = []
        self.logical: bytes | None = None
        self.paths = {name: scratch.with_name(f"{scratch.name}.{i}")
                      for i, name in enumerate((CATALOG_FILE, DISTRIBUTION_FILE, WEIGHTS_FILE))}
        self._fh = {name: path.open("w", encoding="utf-8", newline="\n")
                    for name, path in self.paths.items()}
        self._weights = csv.writer(self._fh[WEIGHTS_FILE], lineterminator="\n")
        self._weights.writerow(("permutation", "index", "file", "exposure_weight"))
        self._closed = False

    def _declarations(self, scenario: ConcreteScenario, row: Row,
                      control: Mapping[str, str]) -> list[osc.Declaration]:
        out = [osc.Declaration(name, kind, control[name], unit, doc)
               for name, kind, unit, doc in osc.CONTROL_PARAMETERS]
        out += [d for d in osc.scenario_declarations(scenario, {"ttc": row.get("ttc")})]
        for name, (unit, kind, doc) in osc.criticality_fields().items():
            if name in row:
                osc_kind = "double" if kind == "float" else "string"
                out.append(osc.Declaration(name, osc_kind, self._text(row[name], osc_kind),
                                           unit, doc))
        return out

    @staticmethod
    def _text(value: Any, kind: str) -> str:
        if value is None:
            return "NaN" if kind == "double" else ""
        if kind == "double":
            return osc.num(value) if not isinstance(value, str) else "NaN"
        if isinstance(value, bool):
            return "true" if value else "false"
        return str(value)

    def add(self, index: int, scenario: ConcreteScenario, row: Row, file: str) -> None:
        if self.reason is not None:
            return
        if len(scenario.objects) != 1:
            self.reason = (f"item {index} has {len(scenario.objects)} objects besides the "
                           "ego; the logical scenario has one cutter")
            return
        missing = [n for n in PARAM_NAMES if n not in scenario.params]
        if missing:
            self.reason = f"item {index} lacks the parameter(s) {', '.join(missing)}"
            return
        entry = scenario_file_name(index).removesuffix(".xosc")
        control = osc.control_values(scenario, entry)
        if self.count == 0:
            self.names = self._declarations(scenario, row, control)
            root = osc.logical_document(
                description="scengen catalogue as one logical cut-in scenario (test mode)",
                date=self.date, declarations=self.names, road_file=ROAD_FILE)
            self.logical = _validated_tree(root, OSC_XSD, LOGICAL_FILE)
            for name in (CATALOG_FILE, DISTRIBUTION_FILE):
                self._fh[name].write(self._head(name))
        # the catalogue entry, validated inside a one-entry catalogue
        wrapper = osc.el(None, "OpenSCENARIO")
        osc.file_header(wrapper, "entry check", self.date)
        catalog = osc.el(wrapper, "Catalog", name=osc.TRAJECTORY_CATALOG)
        traj = osc.cutter_trajectory(catalog, scenario, entry)
        _validated_tree(wrapper, OSC_XSD, f"item {index}: trajectory catalogue entry")
        self._fh[CATALOG_FILE].write(_fragment(traj, 4))
        values = {d.name: d for d in self.names}
        value_set = osc.el(None, "ParameterValueSet")
        for name, decl in values.items():
            if name in control:
                text = control[name]
            elif name in PARAM_NAMES:
                text = osc.num(scenario.params[name])
            elif name == "ttc":
                text = self._text(row.get("ttc"), "double")
            else:
                text = self._text(row.get(name), decl.kind)
            osc.el(value_set, "ParameterAssignment", parameterRef=name, value=text)
        self._fh[DISTRIBUTION_FILE].write(_fragment(value_set, 10))
        weight = row.get("exposure_weight")
        self._weights.writerow((self.count, index, file,
                                "" if weight is None else repr(float(weight))))
        self.count += 1

    def _head(self, name: str) -> str:
        root = osc.root_element()
        if name == CATALOG_FILE:
            osc.file_header(root, "cutter trajectories of a scengen catalogue", self.date)
            osc.el(root, "Catalog", name=osc.TRAJECTORY_CATALOG)
            return _open_head(root, f'<Catalog name="{osc.TRAJECTORY_CATALOG}"/>')
        osc.file_header(root, "the sampled tuples of a scengen catalogue", self.date)
        dist = osc.el(root, "ParameterValueDistribution")
        osc.el(dist, "ScenarioFile", filepath=LOGICAL_FILE)
        osc.el(osc.el(osc.el(dist, "Deterministic"), "DeterministicMultiParameterDistribution"),
               "ValueSetDistribution")
        return _open_head(root, "<ValueSetDistribution/>")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        tails = {CATALOG_FILE: "  </Catalog>\n</OpenSCENARIO>\n",
                 DISTRIBUTION_FILE: ("        </ValueSetDistribution>\n"
                                     "      </DeterministicMultiParameterDistribution>\n"
                                     "    </Deterministic>\n  </ParameterValueDistribution>\n"
                                     "</OpenSCENARIO>\n")}
        for name, fh in self._fh.items():
            if self.reason is None and self.count and name in tails:
                fh.write(tails[name])
            fh.close()

    def remove(self) -> None:
        for path in self.paths.values():
            if path.exists():
                path.unlink()

    def entries(self) -> dict[str, bytes | Path]:
        """Zip entry name -> content (bytes) or the scratch file holding it."""
        if self.reason is not None or self.logical is None:
            return {}
        return {LOGICAL_FILE: self.logical, **self.paths}

    def manifest(self) -> dict[str, Any]:
        if self.reason is not None or self.logical is None:
            return {"included": False, "reason": self.reason or "empty catalogue"}
        return {
            "included": True,
            "scenario_file": LOGICAL_FILE,
            "distribution_file": DISTRIBUTION_FILE,
            "trajectory_catalog": CATALOG_FILE,
            "weights_file": WEIGHTS_FILE,
            "n_permutations": self.count,
            "mode": "test",
            "parameters": [d.name for d in self.names],
            "cutter_motion": "catalogue trajectory per tuple (exact): the sine yaw-rate lane "
                             "change with a speed pulse is no OpenSCENARIO action shape",
        }


_XML_DECL = "<?xml version='1.0' encoding='UTF-8'?>\n"


def _open_head(root: etree._Element, empty: str) -> str:
    """The document's text up to its innermost (empty) element, left open for entries."""
    text: str = etree.tostring(root, encoding="unicode", pretty_print=True)
    head = text[:text.index(empty)]
    return _XML_DECL + head + empty[:-2] + ">\n"


def _fragment(element: etree._Element, indent: int) -> str:
    etree.indent(element, space="  ", level=indent // 2)
    text: str = etree.tostring(element, encoding="unicode", with_tail=False)
    return " " * indent + text + "\n"


def _copy_into(zf: zipfile.ZipFile, name: str, path: Path) -> None:
    info = _zinfo(name)
    info.file_size = os.path.getsize(path)
    with path.open("rb") as src, zf.open(info, "w") as dst:
        while chunk := src.read(1 << 20):
            dst.write(chunk)


def check_index(index: int, fmt: str) -> None:
    if index >= 10**INDEX_DIGITS:
        raise ExportError(f"item {index}: the {fmt} export holds at most {10**INDEX_DIGITS} "
                          "scenarios; split the catalogue")


def write_scratch(items: Iterator[Item], scratch_zip: Path, scratch_csv: Path, fmt: str,
                  file_name: Callable[[int], str],
                  content: Callable[[int, ConcreteScenario, Row, str], bytes]) -> int:
    """The scenario files of a zip export (``content(index, scenario, row, name)`` under
    ``file_name(index)``) in a scratch zip and their index rows (CSV, a leading ``file``
    column) in a scratch CSV, streamed; returns how many. ``assemble_zip`` makes the
    final zip of them."""
    count = 0
    with zipfile.ZipFile(scratch_zip, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zs, \
            scratch_csv.open("w", encoding="utf-8", newline="") as fh:
        index_writer = CsvRowWriter(fh, lead=("file",))
        for index, scenario, _summary, row in items:
            check_index(index, fmt)
            name = file_name(index)
            zs.writestr(name, content(index, scenario, row, name))
            index_writer.write(index, row, (name,))
            count += 1
    return count


def assemble_zip(path: Path, entries: Mapping[str, bytes | Path], scratch_zip: Path) -> None:
    """The final zip: ``entries`` (content or a file holding it) sorted by name, then the
    scenario files of ``scratch_zip`` in their order (their names sort after the others)."""
    with zipfile.ZipFile(path, "w") as zf:
        for name in sorted(entries):
            source = entries[name]
            if isinstance(source, Path):
                _copy_into(zf, name, source)
            else:
                zf.writestr(_zinfo(name), source)
        with zipfile.ZipFile(scratch_zip) as zs:
            for entry in zs.infolist():  # written in index order = name order
                zf.writestr(_zinfo(entry.filename), zs.read(entry))


def write_xosc_zip(items: Iterator[Item], manifest: Mapping[str, Any], path: Path,
                   mode: str = osc.DEFAULT_MODE) -> None:
    """Stream the scenarios into a scratch zip, then assemble the final sorted zip."""
    check_mode(mode)
    if "export" in manifest:
        raise ExportError("manifest: the key 'export' is reserved for the xosc export")
    date = _creation_date(manifest)
    scratch_zip = path.with_name(path.name + ".scenarios")
    scratch_csv = path.with_name(path.name + ".csv")
    logical = LogicalCatalogue(path.with_name(path.name + ".logical"), date)
    extent: RoadExtent | None = None

    def content(index: int, scenario: ConcreteScenario, row: Row, name: str) -> bytes:
        nonlocal extent
        width = _lane_width(scenario, index)
        if extent is None:
            extent = RoadExtent(lane_width=width)
        elif width != extent.lane_width:
            raise ExportError(
                f"item {index}: lane_width {width} m differs from the catalogue's "
                f"{extent.lane_width} m; one xosc export shares one road"
            )
        extent.add(scenario)
        if mode == "test":
            extent.reach(*osc.reach_of_test_run(scenario))
        try:
            data = scenario_xosc(scenario, index=index, row=row, mode=mode, date=date)
        except ExportError as exc:
            raise ExportError(f"item {index}: {exc}") from None
        logical.add(index, scenario, row, name)
        return data

    try:
        count = write_scratch(items, scratch_zip, scratch_csv, "xosc", scenario_file_name,
                              content)
        logical.close()
        assert extent is not None  # an empty catalogue raised in the item stream
        road = road_xodr(extent)
        n_left, n_right = extent.lanes()
        x_start, x_end = extent.x_range()
        full_manifest = dict(manifest)
        full_manifest["export"] = {
            "format": "xosc",
            "mode": mode,
            "n_scenarios": count,
            "openscenario": "1.2",
            "opendrive": "1.7",
            "road_file": ROAD_FILE,
            "index_file": INDEX_FILE,
            "scenario_files": f"scenario_<index, {INDEX_DIGITS} digits>.xosc",
            "logical_scenario": logical.manifest(),
            "lane_width": extent.lane_width,
            "lanes_left_of_ego": n_left,
            "lanes_right_of_ego": n_right,
            "road_x_range": [x_start, x_end],
            "frame": "scengen road frame = OpenSCENARIO world frame: x along the road, "
                     "y left, heading counter-clockwise from +x, z up; ego lane centre y = 0",
            "reference_point": "rear axle, 0.3 length behind the bounding-box centre "
                               "(BoundingBox Center x = 0.3 length, RearAxle positionX = 0)",
            "time": "simulation time 0 = the scenario's first step (t[0] in the scengen.t0 "
                    "header property); replay: absolute timing; test: the cutters' timing "
                    "relative to their start at simulation time 0",
            **({"test_run": {
                "cutter_after_end": "keeps its last velocity up to the time limit",
                "stop": "collision; from the scenario's duration on, the conflict over (the "
                        "ego not faster than any cutter, or ahead of every cutter and not "
                        "slower); the time limit",
                "time_limit_after_duration_s": osc.STOP_SLACK,
                "road": "every vehicle's reach at up to max speed "
                        f"{osc.MAX_SPEED:g} m/s until the time limit",
            }} if mode == "test" else {}),
        }
        entries: dict[str, bytes | Path] = {
            INDEX_FILE: scratch_csv,
            MANIFEST_FILE: (dumps(full_manifest, indent=2) + "\n").encode("utf-8"),
            ROAD_FILE: road,
            **logical.entries(),
        }
        assemble_zip(path, entries, scratch_zip)
    finally:
        logical.close()
        logical.remove()
        for scratch in (scratch_zip, scratch_csv):
            if scratch.exists():
                scratch.unlink()
