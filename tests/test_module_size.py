"""Every module of lapwrench stays small enough to read in one sitting: at most 400 lines (issue 13).

Read with :mod:`pathlib` only; nothing is imported.
"""

from __future__ import annotations

from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "lapwrench"
MAX_LINES = 400


def long_modules(root: Path, limit: int) -> dict[str, int]:
    """The modules under ``root`` longer than ``limit`` lines, with their line counts."""
    counts = {p.relative_to(root).as_posix(): len(p.read_text().splitlines()) for p in root.rglob("*.py")}
    return {name: n for name, n in sorted(counts.items()) if n > limit}


def test_no_module_is_over_400_lines() -> None:
    too_long = long_modules(SRC, MAX_LINES)
    assert not too_long, f"split these modules by job (at most {MAX_LINES} lines each): {too_long}"


def test_the_check_sees_a_long_module(tmp_path: Path) -> None:
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "long.py").write_text("x = 1\n" * (MAX_LINES + 1))
    (tmp_path / "short.py").write_text("x = 1\n" * MAX_LINES)
    assert long_modules(tmp_path, MAX_LINES) == {"pkg/long.py": MAX_LINES + 1}
