"""Where numba keeps the compiled kernels: one directory per version of the kernel sources.

numba's ``cache=True`` keys a kernel's cached machine code on the kernel's own source file.
A kernel that calls one in another file (``criticality.kernels.scene_risks`` calls
``kernels.predict``) keeps its stale code when only the callee's file changed, after an
edit or an upgrade: silently wrong numbers. So, unless the user chose a directory with
``NUMBA_CACHE_DIR``, every module with ``njit(cache=True)`` kernels calls
:func:`register` with its own ``__file__`` before its first ``@njit``. The module joins
the list of registered kernel sources and numba's cache directory becomes
``$XDG_CACHE_HOME/scengen/numba/<hash>`` (default ``~/.cache``), the hash taken over the
bytes of every source registered so far. A module is imported after the modules whose
kernels it calls (it imports them), so its kernels are cached under a hash that covers
its callees: a change to any of them starts a fresh cache. numba reads the directory when
a kernel is decorated, so each module's kernels keep the directory of their registration.
numba checks its own version itself.

No module here knows the others' paths: sampler's kernel modules register themselves.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["cache_dir", "kernel_input", "register", "registered"]

_REGISTERED: list[Path] = []


def registered() -> tuple[Path, ...]:
    """The kernel sources registered so far, in registration order."""
    return tuple(_REGISTERED)


def cache_dir(files: tuple[Path, ...] | None = None) -> Path:
    """The cache directory for these kernel sources as they are now (default: those
    registered so far)."""
    h = hashlib.sha256()
    for path in _REGISTERED if files is None else files:
        h.update(path.name.encode())
        h.update(path.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "scengen" / "numba" / h.hexdigest()[:16]


def kernel_input(values: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """``values`` as the one array type a kernel's input is compiled for: float64,
    C-contiguous and read-only (a read-only view, no copy, when it is already
    float64 and contiguous).

    numba compiles one machine-code version per read-only flag of each array argument, so
    the same kernel fed a writable array in one call and a read-only one (a pandas
    ``to_numpy()`` view, a memoised array) in another is compiled twice: measured (issue
    25), the first ``POST /scenarios`` after the start-up warm-up compiled the criticality
    kernels again for 12-15 s. Entry points pass their inputs through this (outputs stay
    writable)."""
    arr = np.ascontiguousarray(values, dtype=np.float64).view()
    arr.flags.writeable = False
    return arr


def register(module_file: str) -> None:
    """Register a kernel module's source (pass its ``__file__``) and point numba's cache at
    :func:`cache_dir` (unless ``NUMBA_CACHE_DIR`` is set or the directory cannot be made:
    then numba's default, beside the sources). Call it before the module's first
    ``@njit``."""
    path = Path(module_file).resolve()
    if path not in _REGISTERED:
        _REGISTERED.append(path)
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    target = cache_dir()
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    numba.config.CACHE_DIR = str(target)  # type: ignore[attr-defined]  # set at import
