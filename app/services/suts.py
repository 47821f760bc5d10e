"""Systems under test: the registry the CLI and the service choose from (issue 24, item 10).

The registry holds

- riskcore's built-in SUTs (``riskcore.sut.BUILTIN_SUTS``: ``none``, ``r157_cc``,
  ``r157_cc_conflict``, ``rss``, ``idm``, ``acc``, ``acc_aeb``, ``ttr_aeb``), and
- every SUT an installed Python package registers under the entry-point group
  ``scengen.suts`` (``importlib.metadata``): ``name = "package.module:Object"``, where the
  object is a ``riskcore.sut.SutSpec``-like object (``factory`` and, optionally,
  ``summary``, ``parameters``, ``source``), a class of either protocol, or a function
  returning a SUT.

A name shadowing a built-in is left out of the registry (``conflicts`` says so): a built-in
always means what docs/evaluation.md says it means.

HTTP requests choose among registered names only (``resolve(..., allow_import=False)``):
a request never names a module to import. The CLI also takes ``--sut module:Object``
(``allow_import=True``), the same kinds of object as an entry point.

A class is batched (``riskcore.sut.SystemUnderTest``: ``reset(n, seeds)``, ``act(obs)``
on arrays) or per run (``riskcore.sut.PerRunSUT``: ``reset(seed)``, ``act(obs)`` on one
run's scalars): told apart by the number of arguments its ``reset`` takes, or by a class
attribute ``per_run = True``. A per-run class is wrapped with ``riskcore.sut.per_run``.

What this module hands to the campaign runner is a ``SutFactory``: a picklable, zero
argument callable that makes a fresh SUT, so the runs can go to pool or Dask workers (they
import the object's module themselves).
"""

from __future__ import annotations

import functools
import importlib
import inspect
import logging
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

from app import jsonconv
from app.errors import InvalidInput
from app.schemas import SutInfo

log = logging.getLogger("scengen.app")

#: the entry-point group installed packages register their SUTs under
ENTRY_POINT_GROUP = "scengen.suts"


def _riskcore_sut() -> Any:
    """The ``riskcore.sut`` face (imported when first needed: numba kernels)."""
    return importlib.import_module("riskcore.sut")


def _load_object(ref: str) -> Any:
    """``module:attr.path`` → the object (ImportError/AttributeError as ValueError)."""
    module_name, sep, attr = ref.partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"{ref!r} is not of the form module:Object")
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"cannot import module {module_name!r}: {exc}") from None
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ValueError(f"module {module_name!r} has no {attr!r}") from None
    return obj


def _is_per_run_class(cls: type) -> bool:
    """A class whose ``reset`` takes one argument (a seed), or says ``per_run = True``."""
    flag = getattr(cls, "per_run", None)
    if isinstance(flag, bool):
        return flag
    reset = getattr(cls, "reset", None)
    if reset is None:
        return False
    try:
        params = [p for p in inspect.signature(reset).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    except (TypeError, ValueError):
        return False
    # unbound function: (self, seed) is per run, (self, n, seeds) is batched
    return len(params) == 2


@dataclass(frozen=True)
class SutFactory:
    """A picklable recipe for a fresh SUT: a built-in name (``riskcore.sut.make_sut``) or
    an object reference ``module:Object``, with keyword parameters."""

    name: str
    ref: str | None = None  # None: a built-in
    params: tuple[tuple[str, Any], ...] = ()

    def __call__(self) -> Any:
        kwargs = dict(self.params)
        if self.ref is None:
            return _riskcore_sut().make_sut(self.name, **kwargs)
        return _instantiate(_load_object(self.ref), self.name, kwargs)


def _instantiate(obj: Any, name: str, kwargs: Mapping[str, Any]) -> Any:
    """A SUT from what a ``module:Object`` reference points at (module docstring)."""
    factory = getattr(obj, "factory", None)
    if factory is not None and not inspect.isclass(obj):  # a SutSpec
        return factory(**kwargs)
    if inspect.isclass(obj):
        if _is_per_run_class(obj):
            rs = _riskcore_sut()
            return rs.per_run(functools.partial(obj, **kwargs), name)
        sut = obj(**kwargs)
    elif callable(obj):
        sut = obj(**kwargs)
    else:
        raise ValueError(f"{name}: {type(obj).__name__} is neither a SUT class, a factory "
                         "nor a SutSpec")
    if not hasattr(sut, "act") or not hasattr(sut, "reset"):
        raise ValueError(f"{name}: the object made has no reset()/act(); a SUT follows "
                         "riskcore.sut.SystemUnderTest or PerRunSUT")
    return sut


@dataclass(frozen=True)
class SutEntry:
    """One registered SUT: what docs and the dashboard show, and how to make it."""

    name: str
    origin: str  # "builtin" | "entry point (<distribution>)" | "module"
    summary: str = ""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""
    ref: str | None = None  # module:Object (None for a built-in)

    def factory(self, params: Mapping[str, Any] | None = None) -> SutFactory:
        return SutFactory(self.name, self.ref, tuple(sorted((params or {}).items())))

    def info(self) -> SutInfo:
        """What ``GET /suts`` and ``scengen evaluate --list-suts`` show of it (its
        parameters in the service's JSON convention)."""
        return SutInfo(name=self.name, origin=self.origin, summary=self.summary,
                       parameters=jsonconv.encode(dict(self.parameters)), source=self.source)


@dataclass(frozen=True)
class Registry:
    """The registered SUTs by name (built-ins first) and the entry points left out."""

    entries: Mapping[str, SutEntry]
    conflicts: tuple[str, ...] = ()

    def names(self) -> list[str]:
        return list(self.entries)


def _builtin_entries() -> dict[str, SutEntry]:
    out: dict[str, SutEntry] = {}
    for name, spec in _riskcore_sut().BUILTIN_SUTS.items():
        out[str(name)] = SutEntry(
            name=str(name), origin="builtin", summary=str(getattr(spec, "summary", "")),
            parameters=dict(getattr(spec, "parameters", {}) or {}),
            source=str(getattr(spec, "source", "")))
    return out


def _entry_point_entries(builtin: Mapping[str, SutEntry]
                         ) -> tuple[dict[str, SutEntry], list[str]]:
    found: dict[str, SutEntry] = {}
    conflicts: list[str] = []
    for ep in sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        dist = getattr(getattr(ep, "dist", None), "name", None) or "?"
        if ep.name in builtin or ep.name in found:
            conflicts.append(f"{ep.name} ({dist}: {ep.value}) shadows a SUT already "
                             "registered; left out")
            log.warning("SUT entry point %s of %s left out: the name is taken", ep.name, dist)
            continue
        summary, parameters, source = "", {}, ""
        try:  # descriptions only; a broken package fails when it is used, with its error
            obj = ep.load()
            summary = str(getattr(obj, "summary", "") or (inspect.getdoc(obj) or "")
                          .split("\n\n")[0].replace("\n", " "))
            parameters = dict(getattr(obj, "parameters", {}) or {})
            source = str(getattr(obj, "source", "") or "")
        except Exception as exc:
            summary = f"(cannot be loaded: {type(exc).__name__}: {exc})"
        found[ep.name] = SutEntry(name=ep.name, origin=f"entry point ({dist})",
                                  summary=summary, parameters=parameters, source=source,
                                  ref=ep.value)
    return found, conflicts


_lock = threading.Lock()
_cached: Registry | None = None


def registry(refresh: bool = False) -> Registry:
    """Built-ins and the installed entry points (read once per process; ``refresh``
    re-reads them, e.g. after a package was installed)."""
    global _cached
    with _lock:
        if _cached is None or refresh:
            builtin = _builtin_entries()
            extra, conflicts = _entry_point_entries(builtin)
            _cached = Registry({**builtin, **extra}, tuple(conflicts))
        return _cached


def _label(field: str) -> str:
    """How a message names ``field``: ``body.sut`` as ``sut`` (the request's key), a CLI
    option such as ``--sut-param`` as itself."""
    return field.removeprefix("body.")


def resolve(name: str, *, allow_import: bool, field: str = "body.sut",
            reg: Registry | None = None) -> SutEntry:
    """The registered SUT called ``name``; with ``allow_import`` (the CLI only) also a
    ``module:Object`` reference. Anything else is ``InvalidInput`` naming ``field``."""
    reg = registry() if reg is None else reg
    if not isinstance(name, str) or not name.strip():
        raise InvalidInput(f"{_label(field)}: give the name of a registered system under test "
                           f"({', '.join(reg.names())})", field=field)
    name = name.strip()
    if name in reg.entries:
        return reg.entries[name]
    if ":" in name or "/" in name:
        if not allow_import:
            raise InvalidInput(
                f"{_label(field)}: {name!r} looks like a module path; a request chooses among the "
                f"registered SUTs only ({', '.join(reg.names())}); register your own with "
                f"the entry-point group {ENTRY_POINT_GROUP!r}", field=field)
        try:
            obj = _load_object(name)
        except ValueError as exc:
            raise InvalidInput(f"{_label(field)}: {exc}", field=field) from None
        if not (inspect.isclass(obj) or callable(obj)
                or callable(getattr(obj, "factory", None))):
            # a module, a constant...: the reference is wrong, not the parameters
            raise InvalidInput(f"{_label(field)}: {name!r} is a {type(obj).__name__}, not "
                               "a SUT class, a factory or a SutSpec", field=field)
        summary = (inspect.getdoc(obj) or "").split("\n\n")[0].replace("\n", " ")
        declared = getattr(obj, "parameters", None)
        return SutEntry(name=name, origin="module", summary=summary, ref=name,
                        parameters=dict(declared) if isinstance(declared, Mapping) else {},
                        source=str(getattr(obj, "source", "") or ""))
    raise InvalidInput(f"{_label(field)}: unknown system under test {name!r}; registered: "
                       f"{', '.join(reg.names())}"
                       + ("" if not allow_import else " (or give module:Class)"),
                       field=field)


def make_factory(entry: SutEntry, params: Mapping[str, Any] | None = None,
                 field: str = "body.sut_params") -> SutFactory:
    """The entry's factory with ``params``, tried once here so that bad parameters are an
    ``InvalidInput`` naming ``field`` now rather than a failed job later."""
    _check_declared(entry, params or {}, field)
    factory = entry.factory(params)
    try:
        factory()
    except InvalidInput:
        raise
    except (TypeError, ValueError) as exc:
        raise InvalidInput(f"{_label(field)}: {entry.name} refuses them: {exc}",
                           field=field) from None
    return factory


def _check_declared(entry: SutEntry, params: Mapping[str, Any], field: str) -> None:
    """A parameter the SUT declares with a number as its default must be given a number
    (``time_gap=abc`` reached the user's class as a string and failed there as "'>' not
    supported between instances of 'str' and 'int'"). Undeclared names are left to the
    class: its constructor may take more than it lists."""
    for key, value in params.items():
        spec = entry.parameters.get(key)
        default = spec[0] if isinstance(spec, tuple | list) and spec else None
        numeric = isinstance(default, int | float) and not isinstance(default, bool)
        if numeric and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise InvalidInput(f"{_label(field)}: {entry.name}.{key}: expected a number, "
                               f"got {value!r}", field=field)


def list_suts() -> list[SutInfo]:
    """The registered SUTs (``GET /suts``, ``scengen evaluate --list-suts``)."""
    return [e.info() for e in registry().entries.values()]


__all__ = ["ENTRY_POINT_GROUP", "Registry", "SutEntry", "SutFactory", "list_suts",
           "make_factory", "registry", "resolve"]
