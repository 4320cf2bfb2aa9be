"""Joint limits and the envelope met by changing only the lower-priority motion.

The virtual model (eq 1-2) gives a desired joint acceleration a_d. The RCM task is the primary
task: its acceleration J a_d must be kept. The joint limits (a box a_lo <= a <= a_hi from
:class:`~lapwrench.motion.reference_shaper.ReferenceShaper`) and the scope's envelope (rows
lo_k <= c_kᵀ a <= hi_k from :mod:`lapwrench.motion.envelope`) are met by changing only the
lower-priority motion, closest to a_d in the kinetic metric:

    min_a ½ (a - a_d)ᵀ M (a - a_d)   s.t.   J a = J a_d,   a_lo <= a <= a_hi,   envelope rows.

This is the problem Saturation in the Null Space (SNS; Flacco, De Luca, Khatib, IEEE T-RO 2015)
solves greedily, by saturating the most violated joint at its bound until the rest fits. Greedy
saturation can miss a solution that exists: on 40 random states with random null-space demands it
found none in 16 cases where one did (tests/motion/test_saturation.py keeps those cases). So the
problem is solved exactly, as a small hierarchical QP, with the Goldfarb-Idnani dual active-set
method (compiled, :mod:`lapwrench.motion.qp`: a few µs for 7 joints with every row hard, about 15 µs
with the envelope relaxed; ``quadprog`` when the task cannot be kept and as the fallback when round-off
defeats the compiled solver):

1. the RCM task and the robot's joint limits, together (hard constraints);
2. the envelope: first as hard constraints too (the common case, the smaller QP); if levels 1
   and 2 together have no solution, relaxed by slack variables with a weight far above the rest
   (SLACK_WEIGHT), so it is met as closely as level 1 allows (the robot's limits win);
3. the rest of the motion as close as possible to a_d.

If level 1 has no solution, the RCM task cannot be kept inside the joint limits: the result says
so (``feasible = False``) with the acceleration inside the joint limits that comes closest to the
task's, and the caller stops the arm if that lasts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import quadprog

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.motion.qp import QP_INFEASIBLE, QP_NUMERICAL, QP_SOLVED, dual_active_set
from lapwrench.spatial import Mat, Vec, inner

# A row is active when its violation by a_d exceeds this fraction of its scale (round-off guard),
# and counted as saturated in the solution when it lies within this fraction of its bound.
VIOLATION_TOL = 1e-9
# Every row is widened by this fraction of its scale before the solve (1e-6 rad/s² for a joint):
# a box of zero width (the jerk and braking bands meeting) otherwise makes the dual method report
# "inconsistent" on a problem that has a solution (2 of 400 random problems at 1e-9, none at 1e-7).
BOX_WIDENING = 1e-7
# Weight of the envelope's slack against the kinetic metric (per unit of trace(M)/n): the envelope
# gives way only where the hard level leaves it no room.
SLACK_WEIGHT = 1e6
# Weight of the closeness to a_d against the task residual when the task cannot be met (relative).
TASK_FALLBACK_REGULARISATION = 1e-6
# An envelope row whose slack exceeds this (in units of its deceleration scale) counts as relaxed.
RELAXED_TOL = 1e-6
# The compiled relaxed level's solution must meet its (normalised) rows to this, else quadprog solves it:
# round-off in its ill-conditioned metric moves the iterate off active rows by ~3e-7 in random tests.
RELAXED_CHECK_TOL = 1e-5


@dataclass(frozen=True)
class LimitRows:
    """Inequality rows lo <= C a <= hi on the joint acceleration, with names for telemetry.

    ``hard`` rows are the robot's limits; the others (the envelope) give way to them.
    ``scale`` normalises each row's violation so rows in different units can be compared.
    """

    C: Mat
    lo: Vec
    hi: Vec
    scale: Vec
    names: tuple[str, ...]
    hard: np.ndarray

    @staticmethod
    def joint_box(a_lo: Vec, a_hi: Vec, a_max: Vec) -> LimitRows:
        n = a_lo.shape[0]
        eye, names, hard = _box_constants(n)
        return LimitRows(eye, a_lo, a_hi, a_max, names, hard)

    def admits(self, x: Vec) -> bool:
        """True if x meets every row (up to the round-off tolerance)."""
        return not (_violations(self, x) > VIOLATION_TOL).any()

    @staticmethod
    def stack(*parts: LimitRows) -> LimitRows:
        return LimitRows(
            np.vstack([p.C for p in parts]),
            np.concatenate([p.lo for p in parts]),
            np.concatenate([p.hi for p in parts]),
            np.concatenate([p.scale for p in parts]),
            tuple(n for p in parts for n in p.names),
            np.concatenate([p.hard for p in parts]),
        )


@functools.cache
def _box_constants(n: int) -> tuple[Mat, tuple[str, ...], np.ndarray]:
    eye = np.eye(n)
    eye.flags.writeable = False
    hard = np.ones(n, dtype=bool)
    hard.flags.writeable = False
    return eye, tuple(f"joint{i + 1}" for i in range(n)), hard


@dataclass(frozen=True)
class SaturationResult:
    """The chosen acceleration, the rows at a bound, the envelope rows relaxed (``dropped``), feasibility."""

    a: Vec
    saturated: tuple[str, ...]
    dropped: tuple[str, ...]
    feasible: bool


def _violations(rows: LimitRows, a: Vec) -> Vec:
    """Each row's violation, normalised by its scale (<= 0: satisfied)."""
    return row_violations(rows.C, rows.lo, rows.hi, rows.scale, np.ascontiguousarray(a, dtype=np.float64))


@kernel_inlined
def violated(lo: Vec, hi: Vec, y: Vec, scale: Vec) -> bool:
    """True if some row's scaled violation exceeds :data:`VIOLATION_TOL` (:func:`row_violations` without its array)."""
    worst = -np.inf
    for i in range(y.shape[0]):
        worst = max(worst, max(lo[i] - y[i], y[i] - hi[i]) / scale[i])
    return worst > VIOLATION_TOL


@kernel
def row_violations(C: Mat, lo: Vec, hi: Vec, scale: Vec, a: Vec) -> Vec:
    """Each row's violation max(lo - C a, C a - hi), normalised by its scale (<= 0: satisfied)."""
    y = C @ a
    return np.maximum(lo - y, y - hi) / scale


@kernel
def exact_qp(a_d: Vec, M: Mat, J: Mat, C: Mat, lo: Vec, hi: Vec, scale: Vec) -> tuple[Mat, Vec, Mat, Vec]:
    """quadprog's (G, a, C, b) for min ½ (a - a_d)ᵀ M (a - a_d) s.t. J a = J a_d (first rows) and
    lo <= C a <= hi, every row widened by BOX_WIDENING of its scale."""
    k, m, n = J.shape[0], C.shape[0], a_d.shape[0]
    A = np.empty((n, k + 2 * m))
    A[:, :k] = J.T
    A[:, k:k + m] = C.T
    A[:, k + m:] = -C.T
    widen = BOX_WIDENING * scale
    b = np.empty(k + 2 * m)
    b[:k] = J @ a_d
    b[k:k + m] = lo - widen
    b[k + m:] = -hi - widen
    return M.copy(), M @ a_d, A, b


@kernel
def solve_exact(Minv: Mat, a_d: Vec, J: Mat, C: Mat, lo: Vec, hi: Vec, scale: Vec) -> tuple[Vec, int]:
    """Level 1 and 2 as hard rows, compiled: min ½ (a - a_d)ᵀ M (a - a_d) s.t. J a = J a_d and
    lo <= C a <= hi, every row widened by BOX_WIDENING of its scale (:func:`~lapwrench.motion.qp.dual_active_set`)."""
    max_iter = 4 * (J.shape[0] + 2 * C.shape[0]) + 20
    return dual_active_set(Minv, a_d, J, C, lo, hi, BOX_WIDENING * scale, scale, max_iter)


def _solve_exact(a_d: Vec, Minv: Mat, M: Mat, J: Mat, rows: LimitRows) -> Vec | None:
    """min ½ (a - a_d)ᵀ M (a - a_d) s.t. J a = J a_d and every row; None if infeasible."""
    f = np.ascontiguousarray
    C = f(rows.C, dtype=np.float64)
    lo, hi, scale = f(rows.lo, dtype=np.float64), f(rows.hi, dtype=np.float64), f(rows.scale, dtype=np.float64)
    a, status = solve_exact(Minv, a_d, J, C, lo, hi, scale)
    if status == QP_SOLVED:
        return a
    if status == QP_INFEASIBLE:
        return None
    try:  # round-off defeated the compiled solver: quadprog's updated factorisations
        return quadprog.solve_qp(*exact_qp(a_d, M, J, C, lo, hi, scale), J.shape[0])[0]
    except ValueError:  # "constraints are inconsistent" or linearly dependent
        return None


@kernel
def solve_relaxed(Minv: Mat, M: Mat, a_d: Vec, J: Mat, C: Mat, lo: Vec, hi: Vec, scale: Vec,
                  hard: np.ndarray) -> tuple[Vec, Vec, int]:
    """Level 2 relaxed, compiled: min ½ (a - a_d)ᵀ M (a - a_d) + ½ w |σ|² s.t. J a = J a_d, the hard
    rows, and each soft row i relaxed by its slack σᵢ (in units of its scale) on both sides,
    lo_i/s_i - σᵢ <= c_iᵀ a / s_i <= hi_i/s_i + σᵢ, with w = SLACK_WEIGHT trace(M)/n.

    The same :func:`~lapwrench.motion.qp.dual_active_set` on x = [a; σ]: M⁻¹ becomes
    blockdiag(M⁻¹, I/w), the unconstrained optimum [a_d; 0], and a soft row two one-sided rows
    (c_iᵀ a / s_i + σᵢ >= lo_i/s_i and c_iᵀ a / s_i - σᵢ <= hi_i/s_i). Every row is widened by
    BOX_WIDENING (of its scale, the rows being normalised). Returns (a, σ per soft row, status)."""
    n, k, m = a_d.shape[0], J.shape[0], C.shape[0]
    soft = 0
    for i in range(m):
        soft += not hard[i]
    nx, rows = n + soft, m + soft
    w = 0.0
    for i in range(n):
        w += M[i, i]
    w = SLACK_WEIGHT * w / n
    Minv_x = np.zeros((nx, nx))
    Minv_x[:n, :n] = Minv
    x0 = np.zeros(nx)
    x0[:n] = a_d
    E = np.zeros((k, nx))
    E[:, :n] = J
    Cx = np.zeros((rows, nx))
    lo_x = np.empty(rows)
    hi_x = np.empty(rows)
    j = 0
    for i in range(m):
        Cx[i, :n] = C[i] / scale[i]
        lo_x[i], hi_x[i] = lo[i] / scale[i], hi[i] / scale[i]
        if not hard[i]:  # row i keeps its lower side with +σ; row m + j its upper side with -σ
            Minv_x[n + j, n + j] = 1.0 / w
            Cx[i, n + j] = 1.0
            hi_x[i] = np.inf
            Cx[m + j, :n] = Cx[i, :n]
            Cx[m + j, n + j] = -1.0
            lo_x[m + j], hi_x[m + j] = -np.inf, hi[i] / scale[i]
            j += 1
    widen = np.full(rows, BOX_WIDENING)
    x, status = dual_active_set(Minv_x, x0, E, Cx, lo_x, hi_x, widen, np.ones(rows), 4 * (k + 2 * rows) + 20)
    if status == QP_SOLVED and not _meets(x, Cx, lo_x, hi_x, J, a_d):
        status = QP_NUMERICAL  # round-off carried the iterate off an active row: quadprog instead
    return x[:n].copy(), x[n:].copy(), status


@kernel
def _meets(x: Vec, C: Mat, lo: Vec, hi: Vec, J: Mat, a_d: Vec) -> bool:
    """Whether x meets every row lo <= C x <= hi within RELAXED_CHECK_TOL and its first n entries keep
    J a = J a_d to 1e-6 of J a_d (the metric of the relaxed level has a condition number near
    SLACK_WEIGHT, so its solution is checked, not trusted)."""
    for i in range(C.shape[0]):
        y = inner(C[i], x)
        if y < lo[i] - RELAXED_CHECK_TOL or y > hi[i] + RELAXED_CHECK_TOL or not np.isfinite(y):
            return False
    n = a_d.shape[0]
    Ja_d = J @ a_d
    err = J @ x[:n] - Ja_d
    return bool(np.abs(err).max() <= 1e-6 * (1.0 + np.abs(Ja_d).max()))


def _solve(a_d: Vec, Minv: Mat, M: Mat, J: Mat, rows: LimitRows) -> tuple[Vec, Vec] | None:
    """:func:`solve_relaxed`; (a, σ) or None if the hard level is infeasible. quadprog solves the same
    problem when round-off defeats the compiled solver."""
    f = np.ascontiguousarray
    C, lo, hi = f(rows.C, dtype=np.float64), f(rows.lo, dtype=np.float64), f(rows.hi, dtype=np.float64)
    scale = f(rows.scale, dtype=np.float64)
    a, slack, status = solve_relaxed(Minv, M, a_d, J, C, lo, hi, scale, f(rows.hard, dtype=np.bool_))
    if status == QP_SOLVED:
        return a, slack
    if status == QP_INFEASIBLE:
        return None
    return _solve_quadprog(a_d, M, J, rows)


def _solve_quadprog(a_d: Vec, M: Mat, J: Mat, rows: LimitRows) -> tuple[Vec, Vec] | None:
    """:func:`solve_relaxed`'s problem by quadprog (its fallback, and the tests' reference)."""
    n = a_d.shape[0]
    soft = ~rows.hard
    m = int(soft.sum())
    G = np.zeros((n + m, n + m))
    G[:n, :n] = M
    G[n:, n:] = np.eye(m) * (SLACK_WEIGHT * float(np.trace(M)) / n)
    C = np.zeros((len(rows.names), n + m))
    C[:, :n] = rows.C / rows.scale[:, None]
    C[np.flatnonzero(soft), n + np.arange(m)] = 1.0
    E = np.zeros((J.shape[0], n + m))
    E[:, :n] = J
    A = np.vstack([E, C, C * np.where(np.arange(n + m) < n, -1.0, 1.0)]).T
    b = np.concatenate([J @ a_d, rows.lo / rows.scale - BOX_WIDENING, BOX_WIDENING - rows.hi / rows.scale])
    q = np.concatenate([M @ a_d, np.zeros(m)])
    try:
        x = quadprog.solve_qp(G, q, A, b, J.shape[0])[0]
    except ValueError:  # "constraints are inconsistent" or linearly dependent
        return None
    return x[:n], x[n:]


def _closest_task(a_d: Vec, M: Mat, J: Mat, rows: LimitRows) -> Vec:
    """When the task cannot be met: min ½ |J a - J a_d|² + ½ ε (a - a_d)ᵀ M (a - a_d) inside the hard rows.

    The hard rows are the joint box, never empty, so this always has a solution: the task comes as
    close as the robot's limits allow while the caller brings the arm to rest. quadprog, not the
    compiled solver: this metric's condition number (about 1/ε) lets round-off carry the compiled
    iterates off their active bounds (by 1e-4 of a row's scale in tests), and the arm is stopping anyway.
    """
    hard = rows.hard
    eps = TASK_FALLBACK_REGULARISATION * float(np.trace(J @ J.T)) / float(np.trace(M))
    G = J.T @ J + eps * M
    q = J.T @ (J @ a_d) + eps * (M @ a_d)
    A = np.vstack([rows.C[hard], -rows.C[hard]]).T
    tol = BOX_WIDENING * rows.scale[hard]
    b = np.concatenate([rows.lo[hard] - tol, tol - rows.hi[hard]])
    try:
        return quadprog.solve_qp(G, q, A, b, 0)[0]
    except ValueError:
        return a_d


def _saturated(rows: LimitRows, a: Vec) -> tuple[str, ...]:
    """Names of the rows at (or beyond) one of their bounds."""
    at = at_bound(rows.C, rows.lo, rows.hi, rows.scale, np.ascontiguousarray(a, dtype=np.float64))
    return tuple(rows.names[i] for i in np.flatnonzero(at))


@kernel
def at_bound(C: Mat, lo: Vec, hi: Vec, scale: Vec, a: Vec) -> np.ndarray:
    """Which rows lie at (or beyond) one of their bounds, within twice the widening."""
    y = C @ a
    tol = 2.0 * BOX_WIDENING * scale + 1e-12
    return (y >= hi - tol) | (y <= lo + tol)


def saturate(a_d: Vec, J: Mat, M: Mat, rows: LimitRows) -> SaturationResult:
    """The acceleration closest to ``a_d`` (M metric) with J a = J a_d inside ``rows``, by priority.

    Args:
        a_d: Desired joint acceleration from the virtual model (n).
        J: Primary-task Jacobian with independent rows (k x n), e.g. the 2 x n lateral RCM task.
        M: Joint-space inertia (n x n).
        rows: The limits; ``hard`` rows are the robot's, the others the envelope's.
    """
    if not np.isfinite(a_d).all() or rows.admits(a_d):
        return SaturationResult(a_d, (), (), True)
    f = np.ascontiguousarray
    a_d, M, J = f(a_d, dtype=np.float64), f(M, dtype=np.float64), f(J, dtype=np.float64)
    Minv: Mat = np.linalg.inv(M)  # type: ignore[assignment]  # float64 in and out; numpy's stubs: "floating"
    a = _solve_exact(a_d, Minv, M, J, rows)  # every row met: the common case, a smaller QP
    if a is not None:
        return SaturationResult(a, _saturated(rows, a), (), True)
    sol = None if rows.hard.all() else _solve(a_d, Minv, M, J, rows)
    if sol is None:
        a = _closest_task(a_d, M, J, rows)
        return SaturationResult(a, _saturated(rows, a), (), False)
    a, slack = sol
    soft_names = [n for n, h in zip(rows.names, rows.hard, strict=True) if not h]
    relaxed = tuple(n for n, x in zip(soft_names, slack, strict=True) if abs(x) > RELAXED_TOL)
    return SaturationResult(a, _saturated(rows, a), relaxed, True)
