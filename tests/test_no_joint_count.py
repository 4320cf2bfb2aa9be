"""No literal joint count outside the robot specs (issue 13, "Robots as data").

The arm's joint count comes from its spec (:data:`lapwrench.robot.arms.ARM_SPECS`), the
model built from it (``RobotModel.nq``/``nv``) or the limits (:mod:`lapwrench.robot.limits`), never
from a ``7`` written into the code. The scan is static (:mod:`ast`, nothing is imported) over
``src/lapwrench`` and flags a literal 7 where it sizes or checks a joint vector:

- the shape or size argument of an array constructor (``np.zeros(7)``, ``np.eye(7)``,
  ``np.zeros((5, 7))``, ``np.broadcast_to(x, (7,))``, ``rng.normal(0, s, 7)``, ``Growable(7)``...);
- a slice ``a[o : o + 7]`` (a joint vector packed in a row), ``plt.subplots(7, 1)`` (a plot per joint);
- a loop over ``range(7)`` (a ``for`` or a comprehension; ``x in range(7)`` checks a value's domain);
- a comparison of a shape, length or model size with 7 (``q.shape == (7,)``, ``len(q) != 7``,
  ``q.shape[0] == 7``, ``model.nq != 7``);
- per-joint data: a tuple or list of seven number literals, or ``[x] * 7``.

:data:`ALLOWED` lists the modules that *are* robot data.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "lapwrench"
JOINTS = 7  # the count the Franka arms have: what must not be written into the code

ALLOWED: dict[str, str] = {
    "robot/arms/panda.py": "the Panda's spec: start poses, servo gains, limit tables (shared with the FR3)",
    "robot/arms/fr3.py": "the FR3's spec: its limit tables",
    "robot/arms/xarm7.py": "the xArm7's spec: start poses, servo gains, limit tables",
    "hardware/franka.py": "the Franka driver (the hardware path is Franka-only): libfranka's collision thresholds",
}

#: Calls that build an array, and the positions of their arguments that give its shape or size.
SHAPED_CALLS: dict[str, tuple[int, ...]] = {
    "zeros": (0,), "ones": (0,), "empty": (0,), "full": (0,), "eye": (0, 1), "identity": (0,),
    "tril_indices": (0, 2), "triu_indices": (0, 2), "broadcast_to": (1,), "normal": (2,), "uniform": (2,),
    "integers": (2,), "standard_normal": (0,), "random": (0,), "Growable": (0,), "subplots": (0,),
}
SHAPE_KEYWORDS = frozenset({"shape", "size", "N", "M", "n", "m", "width"})
#: Attributes that hold a shape, a size or a joint count.
SIZE_ATTRS = frozenset({"shape", "size", "nq", "nv", "ndim"})


def _is_joints(node: ast.AST) -> bool:
    """The literal 7, or a tuple literal holding it (a shape)."""
    if isinstance(node, ast.Constant):
        return type(node.value) is int and node.value == JOINTS
    return isinstance(node, ast.Tuple) and any(_is_joints(e) for e in node.elts)


def _call_name(call: ast.Call) -> str | None:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None


def _is_size_expr(node: ast.AST) -> bool:
    """``x.shape``, ``x.shape[0]``, ``model.nq``, ``len(x)``..."""
    if isinstance(node, ast.Subscript):
        node = node.value
    if isinstance(node, ast.Attribute):
        return node.attr in SIZE_ATTRS
    return isinstance(node, ast.Call) and _call_name(node) == "len"


def _is_number(node: ast.AST) -> bool:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        node = node.operand
    return isinstance(node, ast.Constant) and type(node.value) in (int, float)


def _range_loops(tree: ast.AST) -> set[int]:
    """ids of the ``range(...)`` calls a loop or comprehension iterates over."""
    iters = [n.iter for n in ast.walk(tree) if isinstance(n, (ast.For, ast.comprehension))]
    return {id(i) for i in iters if isinstance(i, ast.Call) and _call_name(i) == "range"}


def joint_count_literals(source: str) -> list[tuple[int, str]]:
    """(line, code) of each literal joint count in ``source`` (module docstring)."""
    tree = ast.parse(source)
    loops = _range_loops(tree)
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        hit = False
        if isinstance(node, ast.Call):
            name = _call_name(node)
            if name in SHAPED_CALLS:
                args = [node.args[i] for i in SHAPED_CALLS[name] if i < len(node.args)]
                hit = any(_is_joints(a) for a in args) or any(
                    k.arg in SHAPE_KEYWORDS and _is_joints(k.value) for k in node.keywords
                )
            elif name == "range" and id(node) in loops and node.args:
                stop = node.args[1] if len(node.args) > 1 else node.args[0]
                hit = _is_joints(stop)
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            hit = any(_is_joints(s) for s in sides) and any(_is_size_expr(s) for s in sides)
        elif isinstance(node, ast.Slice):
            hit = any(isinstance(b, ast.BinOp) and _is_joints(b.right) for b in (node.lower, node.upper))
        elif isinstance(node, (ast.Tuple, ast.List)):
            hit = len(node.elts) == JOINTS and all(_is_number(e) for e in node.elts)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
            hit = isinstance(node.left, (ast.List, ast.Tuple)) and _is_joints(node.right)
        if hit:
            found.append((node.lineno, ast.unparse(node)))
    return found


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if p.relative_to(SRC).as_posix() not in ALLOWED)


def test_allowed_modules_exist() -> None:
    missing = [m for m in ALLOWED if not (SRC / m).is_file()]
    assert not missing, f"allow-listed modules that no longer exist: {missing}"


def test_no_literal_joint_count_outside_robot_specs() -> None:
    offenders = [
        f"{path.relative_to(SRC).as_posix()}:{line}: {code}"
        for path in _modules()
        for line, code in joint_count_literals(path.read_text(encoding="utf-8"))
    ]
    assert not offenders, "literal joint counts outside the robot specs:\n" + "\n".join(offenders)


@pytest.mark.parametrize(
    "code",
    [
        "np.zeros(7)",
        "np.ones(7)",
        "np.eye(7)",
        "np.zeros((5, 7))",
        "np.full(shape=7, fill_value=1.0)",
        "np.broadcast_to(b, (7,)).copy()",
        "np.tril_indices(7, -1)",
        "rng.normal(0.0, 0.1, 7)",
        "rng.uniform(-0.3, 0.3, size=7)",
        "Growable(7)",
        "row[off['q'] : off['q'] + 7] = q",
        "fig, axes = plt.subplots(7, 1)",
        "for j in range(7):\n    pass",
        "[j for j in range(0, 7)]",
        "ok = q.shape == (7,)",
        "bad = q.shape != (7,)",
        "bad = len(q) != 7",
        "bad = q.shape[0] == 7",
        "bad = model.nq != 7 or model.nv != 7",
        "q0 = (0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785)",
        "tau = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]",
        "v = [1000.0] * 7",
    ],
)
def test_each_pattern_is_caught(code: str) -> None:
    assert joint_count_literals(code), code


@pytest.mark.parametrize(
    "code",
    [
        "np.zeros(model.nv)",
        "np.zeros((5, n))",
        "ok = filter_code in range(7)",  # a value's domain, not a loop over joints
        "out = x.reshape(-1, 7)",  # a detector's output columns
        "ok = shape[1] == 7",  # the same, on a plain tuple
        "_BAD_FORCE = 7",
        "q = np.zeros(3)",
        "k = rng.integers(3, 7)",  # a value range, not a size
        "s = (7, 7)",
        "x = row[o : o + 3]",
        "f'{x:7.4f}'",
        "names = tuple(f'joint{i}' for i in range(1, 8))",
    ],
)
def test_other_sevens_pass(code: str) -> None:
    assert not joint_count_literals(code), code
