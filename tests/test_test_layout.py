"""The layout of the tests (tests/README.md): one ``test_<module>.py`` per source module, in the folder
that mirrors its package, and no test reaching into a private name of lapwrench.

Both checks read the files with :mod:`ast` and :mod:`pathlib` only; nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "lapwrench"
TESTS = ROOT / "tests"

# Modules without a test file of their own, each with the reason. Keep this short: a module leaves the
# list when its test file appears (the stale-entry check below insists).
UNTESTED: dict[str, str] = {
    # perception pieces exercised through the detectors and the CLI
    "perception/train.py": "training needs the training venv (torch, ultralytics)",
}

# Test files that are not about one module (tests/README.md says why).
NOT_A_MODULE: set[str] = {
    "test_layers.py",
    "test_module_size.py",
    "test_no_joint_count.py",
    "test_test_layout.py",
    "hardware/test_faults.py",
    "hardware/test_frankysim_e2e.py",
    "hardware/test_rt_process.py",
    "hardware/test_signals.py",
    "perception/test_shipped_model.py",
    "sim/test_demo_robots.py",
}
NOT_A_MODULE_DIRS = ("fuzz", "examples", "cues")

# Private names a test may use: the public API of named tuples, which starts with an underscore so it
# cannot clash with a field.
PUBLIC_UNDERSCORE = {"_asdict", "_fields", "_field_defaults", "_make", "_replace"}

# (test file, private name) pairs still allowed. Each needs a public seam in a source file this change
# did not own; the comment names the seam.
PRIVATE_ALLOWED: set[tuple[str, str]] = set()  # (test file, private name) pairs still allowed: none


def rel(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def source_modules() -> list[str]:
    """Every module of the package, as its path under src/lapwrench (package ``__init__`` files re-export
    and are covered through their package's modules)."""
    return sorted(rel(p, SRC) for p in SRC.rglob("*.py") if p.name != "__init__.py")


def expected_test_file(module: str) -> Path:
    path = Path(module)
    return TESTS / path.parent / f"test_{path.stem}.py"


def all_test_files() -> list[Path]:
    return sorted(p for p in TESTS.rglob("*.py") if "__pycache__" not in p.parts)


def test_every_module_has_its_test_file() -> None:
    missing = [m for m in source_modules() if m not in UNTESTED and not expected_test_file(m).exists()]
    assert not missing, "modules without tests/<package>/test_<module>.py (add one, or justify in UNTESTED):\n" + (
        "\n".join(f"  {m} -> {rel(expected_test_file(m), ROOT)}" for m in missing)
    )


def test_the_untested_list_holds_no_stale_entry() -> None:
    modules = set(source_modules())
    gone = sorted(m for m in UNTESTED if m not in modules)
    tested = sorted(m for m in UNTESTED if m in modules and expected_test_file(m).exists())
    assert not gone, f"UNTESTED names modules that no longer exist: {gone}"
    assert not tested, f"UNTESTED names modules that now have their test file: {tested}"


def test_every_test_file_is_named_after_a_module() -> None:
    """tests/<dir>/test_<name>.py tests src/lapwrench/<dir>/<name>.py (or the package <name>/)."""
    stray = []
    for path in all_test_files():
        r = rel(path, TESTS)
        if not path.name.startswith("test_") or r in NOT_A_MODULE or r.split("/")[0] in NOT_A_MODULE_DIRS:
            continue
        target = SRC / path.parent.relative_to(TESTS) / path.name.removeprefix("test_")
        if not (target.exists() or target.with_suffix("").is_dir()):
            stray.append(r)
    assert not stray, f"test files named after no module (rename, or list in NOT_A_MODULE with a reason): {stray}"


def private_uses(tree: ast.AST) -> list[tuple[int, str]]:
    """``x._name`` (x not self/cls), ``from lapwrench... import _name`` and ``setattr/getattr(x, "_name")``."""
    found: list[tuple[int, str]] = []

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__") and name not in PUBLIC_UNDERSCORE

    def own(node: ast.expr) -> bool:
        return isinstance(node, ast.Name) and node.id in ("self", "cls")

    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr) and not own(node.value):
            found.append((node.lineno, node.attr))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("lapwrench"):
            found += [(node.lineno, a.name) for a in node.names if private(a.name)]
        elif isinstance(node, ast.Call) and len(node.args) >= 2 and not own(node.args[0]):
            fn = node.func
            name = fn.id if isinstance(fn, ast.Name) else fn.attr if isinstance(fn, ast.Attribute) else ""
            arg = node.args[1]
            named = isinstance(arg, ast.Constant) and isinstance(arg.value, str) and private(arg.value)
            if name in ("setattr", "getattr", "hasattr", "delattr") and named:
                found.append((node.lineno, arg.value))  # type: ignore[attr-defined]
    return sorted(found)


def test_no_test_uses_a_private_name() -> None:
    hits = []
    for path in all_test_files():
        r = rel(path, TESTS)
        for line, name in private_uses(ast.parse(path.read_text(), str(path))):
            if (r, name) not in PRIVATE_ALLOWED:
                hits.append(f"tests/{r}:{line}: {name}")
    assert not hits, "tests reach into private names (go through the public interface):\n" + "\n".join(hits)


def test_the_private_checker_sees_each_form() -> None:
    code = """
from lapwrench.x import _hidden, shown
import helpers
obj._state = 1
self._mine = 2
monkeypatch.setattr(mod, "_fn", None)
getattr(self, "_warm", False)
row._asdict()
"""
    assert [n for _, n in private_uses(ast.parse(code))] == ["_hidden", "_state", "_fn"]
