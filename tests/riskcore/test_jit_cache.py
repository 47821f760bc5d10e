"""One numba cache directory per version of the kernel sources (riskcore/jit.py)."""

from __future__ import annotations

import ast
import importlib
import re
import shutil
from pathlib import Path

import numba
import pytest

from riskcore import jit

ROOT = Path(__file__).resolve().parents[2]
_FIRST_KERNEL = re.compile(r"^@(numba\.)?njit\(", re.M)


def _kernel_modules() -> list[str]:
    """Every module of the project with a numba kernel, as a dotted name."""
    found = []
    for pkg in ("riskcore", "sampler", "datasets", "app"):
        for p in sorted((ROOT / pkg).rglob("*.py")):
            if _FIRST_KERNEL.search(p.read_text()):
                found.append(".".join(p.relative_to(ROOT).with_suffix("").parts))
    return found


def test_every_kernel_module_registers_before_its_first_kernel() -> None:
    modules = _kernel_modules()
    assert len(modules) >= 5
    for name in modules:
        text = (ROOT / (name.replace(".", "/") + ".py")).read_text()
        assert "jit.register(__file__)" in text, name
        first = _FIRST_KERNEL.search(text)
        assert first is not None
        assert text.index("jit.register(__file__)") < first.start(), name


def _imported_modules(name: str) -> set[str]:
    tree = ast.parse((ROOT / (name.replace(".", "/") + ".py")).read_text())
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_a_module_is_registered_after_the_kernel_modules_it_calls() -> None:
    """The cache directory of a module's kernels is hashed over what was registered before
    it: its callees must be among them, or an edit of a callee would leave stale code."""
    modules = _kernel_modules()
    for name in modules:
        importlib.import_module(name)
    order = [".".join(p.relative_to(ROOT).with_suffix("").parts) for p in jit.registered()]
    assert sorted(order) == sorted(modules)
    for name in modules:
        for callee in _imported_modules(name) & set(modules):
            assert order.index(callee) < order.index(name), (name, callee)


def test_the_directory_follows_every_registered_file(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    modules = _kernel_modules()
    files = []
    for name in modules:
        rel = Path(name.replace(".", "/") + ".py")
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, tmp_path / rel)
        files.append(tmp_path / rel)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    first = jit.cache_dir(tuple(files))
    assert first.parent == tmp_path / "cache" / "scengen" / "numba"
    assert jit.cache_dir(tuple(files)) == first  # stable
    for path in files:  # an edit of any one (e.g. only a callee) moves it
        original = path.read_bytes()
        path.write_bytes(original + b"\n# edited\n")
        assert jit.cache_dir(tuple(files)) != first, path
        path.write_bytes(original)
    assert jit.cache_dir(tuple(files)) == first


def test_compiled_kernels_live_in_the_directory_of_their_registration() -> None:
    from riskcore import kernels
    from riskcore.criticality import kernels as criticality_kernels

    files = jit.registered()
    for module, kernel in ((kernels, kernels.predict),
                           (criticality_kernels, criticality_kernels.scene_risks)):
        upto = files[: files.index(Path(module.__file__).resolve()) + 1]
        cache_path = Path(kernel._cache._cache_path)  # numba's own record of it
        assert cache_path.parent == jit.cache_dir(upto), module.__name__


def test_register_uses_it_unless_the_user_chose(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    jit.register(jit.__file__.replace("jit.py", "kernels.py"))
    assert str(jit.cache_dir()) == numba.config.CACHE_DIR
    assert Path(numba.config.CACHE_DIR).is_dir()
    monkeypatch.setattr(numba.config, "CACHE_DIR", "/the/users/choice")
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/the/users/choice")
    jit.register(jit.__file__.replace("jit.py", "kernels.py"))
    assert numba.config.CACHE_DIR == "/the/users/choice"


def test_kernel_input_is_one_array_type_whatever_comes_in() -> None:
    """Issue 25 item 4: numba compiles a kernel once per read-only flag of its array
    arguments, so entry points hand every kernel a read-only float64 C array."""
    import numpy as np

    from riskcore.jit import kernel_input

    writable = np.arange(6.0).reshape(2, 3)
    frozen = writable.copy()
    frozen.flags.writeable = False
    for given in (writable, frozen, writable.T, [[1, 2, 3]], writable.astype(np.float32)):
        arr = kernel_input(given)
        assert arr.dtype == np.float64 and arr.flags.c_contiguous
        assert not arr.flags.writeable
        np.testing.assert_array_equal(arr, np.asarray(given, dtype=np.float64))
    view = kernel_input(writable)
    assert np.shares_memory(view, writable)  # a view: no copy
    assert writable.flags.writeable  # the caller's array stays writable
