"""lapwrench's import layers: every import points down the layer table, and no imports form a cycle.

The scan is static (:mod:`ast`, nothing is imported) and sees every ``import`` statement in
``src/lapwrench``: at module level, inside functions (lazy imports), under ``if TYPE_CHECKING:``
and in ``try`` blocks; plus ``importlib.import_module("lapwrench.…")`` with a literal name. A lazy
import is still a dependency: a layer must not reach up, whenever the import runs.

:data:`LAYERS` is the table, lowest layer first. A *unit* is a top-level module
(``lapwrench.loop``), a first-level subpackage with everything under it (``lapwrench.sim``), or a
single module named explicitly (``lapwrench.perception.cli``); a module belongs to the unit with
the longest matching name. A module may import from its own layer and from any lower one, never
from a higher one. It follows ``../shared/design.md`` (model → control → loop → world → apps),
finer where the code needs an order inside a group:

- ``base``: no lapwrench imports except inside the layer (the package root, the numba kernel
  decorator, the YAML reader and the config tree, the lock-free latest-value buffer, the command
  lines' argument types).
- ``spatial``: the SE(3)/wrench algebra and smooth shaping functions every equation uses.
- ``robot``: the description, the Pinocchio model and the joint limits.
- ``sensors``: the readings the controller consumes (their validation uses the joint limits).
- ``geometry``: the RCM geometry and its adaptation.
- ``control-terms``: the wrenches, their allocation and the motion layer (reference shaping,
  envelope, saturation).
- ``control``: one controller tick (tick core, compiled tick, :class:`Controller`).
- ``loop``: what runs the tick against a robot: sources, the robot interface, the safety
  supervisor, the control loop and the virtual (engine-free) closed loop.
- ``drivers`` < ``perception`` < ``sim`` < ``hardware``: the world. Perception never imports the
  simulation; the simulation uses perception's detectors; the hardware runners host the loop and
  can run the simulated robot in place of the Franka.
- ``study``: sweeps and tuning on Ray, above the world whose scenarios they run many times.
- ``apps``: the command line. ``lapwrench.perception.cli`` is its own unit here, in this layer,
  although it sits in ``perception/``: its ``dataset`` command renders with the simulator
  (:mod:`lapwrench.sim.dataset`). Moving that command next to the simulator would let it join
  ``lapwrench.perception`` again.

Two checks are separate from the order: no cycle between modules (a cycle inside one unit is
still a cycle) and none between units (the unit graph must be a DAG).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import NamedTuple

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
ROOT = "lapwrench"

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("base", ("lapwrench", "lapwrench.jit", "lapwrench.config_yaml", "lapwrench.config_ranges", "lapwrench.plugins",
              "lapwrench.config_cues", "lapwrench.config", "lapwrench.buffer", "lapwrench.cli_types")),
    ("spatial", ("lapwrench.spatial", "lapwrench.shaping")),
    ("robot", ("lapwrench.robot",)),
    ("sensors", ("lapwrench.inputs", "lapwrench.sensors")),
    ("geometry", ("lapwrench.rcm",)),
    ("control-terms", ("lapwrench.wrenches", "lapwrench.allocation", "lapwrench.motion")),
    ("control", ("lapwrench.tick_params", "lapwrench.tick_core", "lapwrench.tick_entry", "lapwrench.compiled_tick",
                 "lapwrench.controller")),
    (
        "loop",
        (
            "lapwrench.sources", "lapwrench.robot_interface", "lapwrench.safety", "lapwrench.loop_stats",
            "lapwrench.loop", "lapwrench.virtual",
        ),
    ),
    ("drivers", ("lapwrench.drivers",)),
    ("perception", ("lapwrench.perception",)),
    ("sim", ("lapwrench.sim",)),
    ("hardware", ("lapwrench.hardware",)),
    ("study", ("lapwrench.study",)),
    ("apps", ("lapwrench.cli", "lapwrench.__main__", "lapwrench.perception.cli", "lapwrench.ui")),
)
"""Lowest layer first: (layer name, its units). See the module docstring."""


class Import(NamedTuple):
    """One import of a lapwrench module: who imports what, where, and whether it runs lazily."""

    source: str
    target: str
    line: int
    lazy: bool


def module_name(path: Path, src: Path = SRC) -> str:
    """``src/lapwrench/sim/loop.py`` -> ``lapwrench.sim.loop``; a package's ``__init__`` is the package."""
    parts = path.relative_to(src).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def find_modules(src: Path = SRC) -> dict[str, Path]:
    """Every module of the package under ``src``, by dotted name."""
    return {module_name(p, src): p for p in sorted((src / ROOT).rglob("*.py"))}


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute module a ``from … import`` names (relative imports resolved against ``module``)."""
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _targets(node: ast.AST, module: str, is_package: bool, modules: Iterable[str]) -> list[str]:
    """The lapwrench modules one node imports (``from pkg import mod`` names the module itself)."""
    known = set(modules)
    names: list[str] = []
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    elif isinstance(node, ast.ImportFrom):
        base = _absolute(node, module, is_package)
        subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known]
        names = subs if len(subs) == len(node.names) else [base, *subs]
    elif (
        isinstance(node, ast.Call)
        and (getattr(node.func, "attr", None) == "import_module" or getattr(node.func, "id", None) == "import_module")
        and node.args
        and isinstance(node.args[0], ast.Constant)
        and isinstance(node.args[0].value, str)
    ):
        names = [node.args[0].value]
    return [n for n in names if n == ROOT or n.startswith(ROOT + ".")]


def scan_source(text: str, module: str, is_package: bool = False, modules: Iterable[str] = ()) -> list[Import]:
    """Every lapwrench import in one module's source, marking those inside a function as lazy."""
    found: list[Import] = []

    def visit(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = lazy or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            for target in _targets(child, module, is_package, modules):
                found.append(Import(module, target, getattr(child, "lineno", 0), inner))
            visit(child, inner)

    visit(ast.parse(text), False)
    return found


def scan(src: Path = SRC) -> list[Import]:
    """Every lapwrench import of every module under ``src``."""
    modules = find_modules(src)
    return [
        imp
        for name, path in modules.items()
        for imp in scan_source(path.read_text(), name, path.name == "__init__.py", modules)
    ]


def unit_of(module: str, units: Iterable[str]) -> str | None:
    """The unit a module belongs to: the longest unit name equal to it or a package above it."""
    matches = [u for u in units if module == u or module.startswith(u + ".")]
    return max(matches, key=len) if matches else None


def layer_index(layers: tuple[tuple[str, tuple[str, ...]], ...] = LAYERS) -> dict[str, int]:
    """Unit -> its layer's position in the table (0 = lowest)."""
    return {unit: i for i, (_, units) in enumerate(layers) for unit in units}


def upward_imports(imports: Iterable[Import], layers: tuple[tuple[str, tuple[str, ...]], ...] = LAYERS) -> list[str]:
    """One line per import that points to a higher layer than its own module's."""
    index = layer_index(layers)
    bad = []
    for imp in imports:
        a, b = unit_of(imp.source, index), unit_of(imp.target, index)
        if a is None or b is None or index[b] <= index[a]:
            continue
        lazy = " (lazy)" if imp.lazy else ""
        bad.append(
            f"{imp.source} [{layers[index[a]][0]}] imports {imp.target} [{layers[index[b]][0]}] "
            f"at line {imp.line}{lazy}"
        )
    return bad


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return sorted(found)


def module_graph(imports: Iterable[Import]) -> dict[str, set[str]]:
    """Module -> the lapwrench modules it imports (self-imports dropped)."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.source != imp.target:
            graph.setdefault(imp.source, set()).add(imp.target)
    return graph


def unit_graph(imports: Iterable[Import], units: Iterable[str]) -> dict[str, set[str]]:
    """Unit -> the other units its modules import."""
    units = list(units)
    graph: dict[str, set[str]] = {}
    for imp in imports:
        a, b = unit_of(imp.source, units), unit_of(imp.target, units)
        if a and b and a != b:
            graph.setdefault(a, set()).add(b)
    return graph


@pytest.fixture(scope="module")
def imports() -> list[Import]:
    return scan()


def test_the_scan_sees_lazy_type_checking_relative_and_importlib_imports() -> None:
    text = (
        "from typing import TYPE_CHECKING\n"
        "import lapwrench.spatial\n"
        "from . import loop\n"
        "if TYPE_CHECKING:\n"
        "    from lapwrench.robot.model import RobotModel\n"
        "def f():\n"
        "    from lapwrench.hardware import supervisor\n"
        "    import importlib\n"
        "    return importlib.import_module('lapwrench.sim.world')\n"
    )
    modules = ["lapwrench.hardware.supervisor", "lapwrench.sim.loop"]
    found = scan_source(text, "lapwrench.sim.scenarios", modules=modules)
    assert [(i.target, i.lazy) for i in found] == [
        ("lapwrench.spatial", False),
        ("lapwrench.sim.loop", False),
        ("lapwrench.robot.model", False),
        ("lapwrench.hardware.supervisor", True),
        ("lapwrench.sim.world", True),
    ]


def test_the_checks_catch_an_upward_import_and_a_cycle() -> None:
    """The checks can fail: a lazy import of the sim from the controller breaks both."""
    imports = [
        Import("lapwrench.sim.loop", "lapwrench.controller", 1, False),
        Import("lapwrench.controller", "lapwrench.sim.world", 9, True),
        Import("lapwrench.sim.world", "lapwrench.sim.loop", 3, False),
    ]
    assert upward_imports(imports) == [
        "lapwrench.controller [control] imports lapwrench.sim.world [sim] at line 9 (lazy)"
    ]
    assert cycles(module_graph(imports)) == [["lapwrench.controller", "lapwrench.sim.loop", "lapwrench.sim.world"]]
    assert cycles(unit_graph(imports, layer_index())) == [["lapwrench.controller", "lapwrench.sim"]]


def test_every_module_is_in_a_layer() -> None:
    index = layer_index()
    assert [m for m in find_modules() if unit_of(m, index) is None] == []
    assert [u for u in index if not any(m == u or m.startswith(u + ".") for m in find_modules())] == [], (
        "units in the table without a module"
    )


def test_no_import_points_up_the_layers(imports: list[Import]) -> None:
    assert upward_imports(imports) == []


def test_no_import_cycle_between_modules(imports: list[Import]) -> None:
    assert cycles(module_graph(imports)) == []


def test_no_import_cycle_between_units(imports: list[Import]) -> None:
    assert cycles(unit_graph(imports, layer_index())) == []
