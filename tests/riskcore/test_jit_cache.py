"""One numba cache directory per version of the kernel sources (riskcore/_jit_cache.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numba
import pytest

from riskcore import _jit_cache

ROOT = Path(__file__).resolve().parents[2]


def test_every_kernel_file_is_listed_and_configures_the_cache_first() -> None:
    found = sorted(str(p.relative_to(ROOT)) for pkg in ("riskcore", "sampler", "datasets", "app")
                   for p in (ROOT / pkg).rglob("*.py") if "njit(" in p.read_text())
    assert found == sorted(_jit_cache.KERNEL_FILES)
    for rel in found:
        text = (ROOT / rel).read_text()
        assert text.index("_jit_cache.configure()") < text.index("njit("), rel


def test_the_directory_follows_every_kernel_file(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    for rel in _jit_cache.KERNEL_FILES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, tmp_path / rel)
    monkeypatch.setattr(_jit_cache, "_ROOT", tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    first = _jit_cache.cache_dir()
    assert first.parent == tmp_path / "cache" / "scengen" / "numba"
    assert _jit_cache.cache_dir() == first  # stable
    for rel in _jit_cache.KERNEL_FILES:  # an edit of any one (e.g. only a callee) moves it
        path = tmp_path / rel
        original = path.read_bytes()
        path.write_bytes(original + b"\n# edited\n")
        assert _jit_cache.cache_dir() != first, rel
        path.write_bytes(original)
    assert _jit_cache.cache_dir() == first


def test_configure_uses_it_unless_the_user_chose(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    _jit_cache.configure()
    assert str(_jit_cache.cache_dir()) == numba.config.CACHE_DIR
    assert Path(numba.config.CACHE_DIR).is_dir()
    monkeypatch.setattr(numba.config, "CACHE_DIR", "/the/users/choice")
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/the/users/choice")
    _jit_cache.configure()
    assert numba.config.CACHE_DIR == "/the/users/choice"
