"""constraints.txt (the exact versions `make install` applies) agrees with pyproject.toml and
with what is installed, so a fresh clone gets the environment the suite passed on."""

from __future__ import annotations

import importlib.metadata
import tomllib
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]


def _pins(text: str) -> dict[str, Version]:
    pins: dict[str, Version] = {}
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        name, sep, version = line.partition("==")
        assert sep, f"constraints.txt: {line!r} is not an exact pin (name==version)"
        pins[canonicalize_name(name)] = Version(version)
    return pins


def _requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    reqs = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        reqs.extend(extra)
    return [Requirement(r) for r in reqs]


def _problems(reqs: list[Requirement], pins: dict[str, Version]) -> list[str]:
    """Each requirement must be pinned, at a version its range allows."""
    out = []
    for req in reqs:
        pin = pins.get(canonicalize_name(req.name))
        if pin is None:
            out.append(f"{req.name}: not pinned")
        elif not req.specifier.contains(pin, prereleases=True):
            out.append(f"{req.name}: pinned {pin}, outside {req.specifier}")
    return out


def test_every_requirement_is_pinned_inside_its_range() -> None:
    pins = _pins((ROOT / "constraints.txt").read_text(encoding="utf-8"))
    assert _problems(_requirements(), pins) == []


def test_the_check_finds_a_missing_or_out_of_range_pin() -> None:
    pins = {"numpy": Version("1.25.0")}
    problems = _problems([Requirement("numpy>=1.26"), Requirement("scipy>=1.11")], pins)
    assert problems == ["numpy: pinned 1.25.0, outside >=1.26", "scipy: not pinned"]


def test_installed_versions_are_the_pinned_ones() -> None:
    pins = _pins((ROOT / "constraints.txt").read_text(encoding="utf-8"))
    assert len(pins) > 50  # the whole environment, transitive dependencies included
    drift = {}
    for name, pin in pins.items():
        installed = Version(importlib.metadata.version(name))
        if installed != pin:
            drift[name] = f"installed {installed}, pinned {pin}"
    assert drift == {}, "run `make install` (or `make lock` after changing dependencies)"
