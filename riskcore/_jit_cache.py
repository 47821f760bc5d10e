"""Where numba keeps the compiled kernels: one directory per version of the kernel sources.

numba's ``cache=True`` keys a kernel's cached machine code on the kernel's own source file.
A kernel that calls one in another file (``_criticality_kernels.scene_risks`` calls
``_kernels.predict``) keeps its stale code when only the callee's file changed, after an
edit or an upgrade: silently wrong numbers. So, unless the user chose a directory with
``NUMBA_CACHE_DIR``, every kernel module calls :func:`configure` before its first
``@njit`` and the caches go to ``$XDG_CACHE_HOME/scengen/numba/<hash>`` (default
``~/.cache``), the hash taken over all of :data:`KERNEL_FILES`: a change to any of them
starts a fresh cache. numba checks its own version itself.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba

__all__ = ["KERNEL_FILES", "cache_dir", "configure"]

#: every file of the project with a numba kernel (a test checks the list is complete)
KERNEL_FILES = ("riskcore/_kernels.py", "riskcore/_criticality_kernels.py",
                "sampler/kinematics.py", "sampler/criticality.py", "sampler/btn_bound.py")

_ROOT = Path(__file__).resolve().parents[1]


def cache_dir() -> Path:
    """The cache directory for the kernel sources as they are now."""
    h = hashlib.sha256()
    for rel in KERNEL_FILES:
        h.update(rel.encode())
        h.update((_ROOT / rel).read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "scengen" / "numba" / h.hexdigest()[:16]


def configure() -> None:
    """Point numba's cache at :func:`cache_dir` (unless ``NUMBA_CACHE_DIR`` is set or the
    directory cannot be made: then numba's default, beside the sources)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    numba.config.CACHE_DIR = str(path)  # type: ignore[attr-defined]  # set at import
