"""The house's rules that import-linter cannot express (docs/architecture.md):

- a module of one package imports another package only through a face: the package itself
  or one of its subpackages (``sampler``, ``sampler.region``, ``riskcore.criticality``),
  never a plain module inside it (``sampler.region.constraints``);
- nothing imports a name, or a module, starting with ``_`` from another package;
- every face lists its public names in ``__all__`` and defines each of them.

The layering itself is ``lint-imports`` (``[tool.importlinter]`` in pyproject.toml).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "sampler", "riskcore", "datasets")


def _is_package(module: str) -> bool:
    return (ROOT / module.replace(".", "/") / "__init__.py").is_file()


def _cross_package_imports() -> list[tuple[str, int, str, list[str]]]:
    """(file, line, imported module, names) of every import of another package."""
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            rel = str(path.relative_to(ROOT))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    if node.module.split(".")[0] in PACKAGES and not node.module.startswith(pkg):
                        found.append((rel, node.lineno, node.module,
                                      [a.name for a in node.names]))
                elif isinstance(node, ast.Import):
                    for alias in node.names:
                        top = alias.name.split(".")[0]
                        if top in PACKAGES and top != pkg:
                            found.append((rel, node.lineno, alias.name, []))
    return found


def test_there_are_cross_package_imports_to_check() -> None:
    assert len(_cross_package_imports()) > 50  # the check below looks at something


def test_other_packages_are_imported_through_their_faces() -> None:
    bypassing = [f"{f}:{line} imports {mod}" for f, line, mod, _ in _cross_package_imports()
                 if not _is_package(mod)]
    assert bypassing == []


def test_no_private_name_crosses_a_package_boundary() -> None:
    private = [f"{f}:{line} {mod} {names}" for f, line, mod, names in _cross_package_imports()
               if any(p.startswith("_") for p in mod.split("."))
               or any(n.startswith("_") for n in names)]
    assert private == []


def _faces() -> list[str]:
    # app is the top floor: no other package imports it, so it keeps no faces
    return sorted(".".join(p.parent.relative_to(ROOT).parts)
                  for pkg in PACKAGES if pkg != "app" for p in (ROOT / pkg).rglob("__init__.py"))


@pytest.mark.parametrize("face", _faces())
def test_every_face_defines_what_it_lists(face: str) -> None:
    module = importlib.import_module(face)
    listed = getattr(module, "__all__", None)
    assert listed, f"{face} has no __all__"
    assert len(set(listed)) == len(listed), f"{face}: a name is listed twice"
    missing = [name for name in listed if not hasattr(module, name)]
    assert missing == []
    assert all(not name.startswith("_") for name in listed)
