"""lapwrench.jit: the compiled-kernel cache is keyed by the source of every kernel module."""

from __future__ import annotations

from pathlib import Path

import numba
import pytest

from lapwrench import jit


def test_the_cache_folder_is_the_one_numba_uses_and_is_named_by_the_source_hash() -> None:
    assert str(jit.cache_dir()) == numba.config.CACHE_DIR
    assert Path(numba.config.CACHE_DIR).name == jit.source_hash()


def test_a_change_to_any_kernel_module_changes_the_key(tmp_path: Path) -> None:
    """numba alone would keep a caller's cached code when only its callee's file changed."""
    (tmp_path / "motion").mkdir()
    callee = tmp_path / "motion" / "qp.py"
    callee.write_text("@kernel\ndef f(x):\n    return x + 1\n")
    (tmp_path / "tick.py").write_text("@kernel\ndef g(x):\n    return f(x)\n")
    (tmp_path / "cli.py").write_text("print('no kernels here')\n")
    before = jit.source_hash(tmp_path)
    (tmp_path / "cli.py").write_text("print('still none')\n")
    assert jit.source_hash(tmp_path) == before  # a module without kernels does not invalidate the cache
    callee.write_text("@kernel\ndef f(x):\n    return x + 2\n")
    assert jit.source_hash(tmp_path) != before


def test_an_unwritable_cache_root_falls_back_to_the_next(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker / "sub"))  # under a file: cannot be created
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert jit.cache_dir().is_relative_to(tmp_path / "xdg")


def test_cache_is_warm_says_whether_this_versions_kernels_were_compiled_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The demo says a first run compiles (minutes) instead of sitting at 0 % without a word."""
    from lapwrench.config import load
    from lapwrench.controller import Controller

    Controller(load())  # compiled (or loaded) into the real cache
    assert jit.cache_is_warm() or not jit.jit_enabled()
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))  # a version never compiled: an empty folder
    assert not jit.cache_is_warm() or not jit.jit_enabled()
