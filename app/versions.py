"""The one list of versions that ends in results (``GET /version``, export manifests)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from app import __version__

__all__ = ["LIBRARIES", "versions"]

#: the libraries whose numbers or files a result depends on (GET /version and every export
#: manifest list the same ones)
LIBRARIES = ("numpy", "scipy", "pandas", "scikit-learn", "emcee", "numba", "fastapi",
             "sqlalchemy", "distributed", "scenariogeneration")


def versions(libraries: tuple[str, ...] = LIBRARIES) -> dict[str, str | None]:
    """Versions of scengen and of ``libraries`` (None: not installed)."""
    out: dict[str, str | None] = {"scengen": __version__}
    for name in libraries:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out
