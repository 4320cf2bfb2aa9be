"""The compiled dual active-set QP (motion/qp.py) against quadprog, the reference implementation of
the same method, on random saturation problems: same solution or the same verdict of infeasibility."""

from __future__ import annotations

import numpy as np
import pytest
import quadprog

from lapwrench.motion.qp import QP_INFEASIBLE, QP_NUMERICAL, QP_SOLVED, dual_active_set
from lapwrench.motion.saturation import BOX_WIDENING, exact_qp, solve_exact

N = 7


def _problem(rng: np.random.Generator, feasible: bool, envelope: bool) -> tuple[np.ndarray, ...]:
    """M, J, C, lo, hi, scale, a_d of the saturation problem's shape: a joint box, maybe four more rows."""
    A = rng.standard_normal((N, N))
    M = A @ A.T + 0.5 * np.eye(N)
    J = rng.standard_normal((2, N))
    C = np.vstack([np.eye(N), rng.standard_normal((4, N))]) if envelope else np.eye(N)
    m = C.shape[0]
    lo, hi = -rng.uniform(0.1, 5.0, m), rng.uniform(0.1, 5.0, m)
    scale = rng.uniform(0.5, 20.0, m)
    if feasible:  # a point inside every row that meets the task: a_d = it + any null-space motion
        x = rng.uniform(-0.05, 0.05, N)
        lo, hi = np.minimum(lo, C @ x - 0.01), np.maximum(hi, C @ x + 0.01)
        a_d = x + (np.eye(N) - np.linalg.pinv(J) @ J) @ (20.0 * rng.standard_normal(N))
    else:
        lo, hi = lo + 3.0, hi + 3.0  # often no point of the box meets the task
        a_d = 10.0 * rng.standard_normal(N)
    return M, J, C, lo, hi, scale, a_d


def _quadprog(M: np.ndarray, J: np.ndarray, C: np.ndarray, lo: np.ndarray, hi: np.ndarray, scale: np.ndarray,
              a_d: np.ndarray) -> np.ndarray | None:
    try:
        return quadprog.solve_qp(*exact_qp(a_d, M, J, C, lo, hi, scale), J.shape[0])[0]
    except ValueError:
        return None


@pytest.mark.parametrize("envelope", [False, True])
@pytest.mark.parametrize("feasible", [False, True])
def test_the_compiled_solver_agrees_with_quadprog(feasible: bool, envelope: bool) -> None:
    rng = np.random.default_rng(int(feasible) * 2 + int(envelope))
    solved = infeasible = 0
    for _ in range(300):
        M, J, C, lo, hi, scale, a_d = _problem(rng, feasible, envelope)
        ref = _quadprog(M, J, C, lo, hi, scale, a_d)
        a, status = solve_exact(np.linalg.inv(M), a_d, J, C, lo, hi, scale)
        if ref is None:
            assert status == QP_INFEASIBLE
            infeasible += 1
        else:
            assert status == QP_SOLVED
            np.testing.assert_allclose(a, ref, atol=1e-7 * (1.0 + np.abs(ref).max()))
            np.testing.assert_allclose(J @ a, J @ a_d, atol=1e-9 * (1.0 + np.abs(J @ a_d).max()))
            tol = 2.0 * BOX_WIDENING * scale
            assert np.all(C @ a >= lo - tol) and np.all(C @ a <= hi + tol)
            solved += 1
    assert solved > 100 if feasible else infeasible > 100  # the cases were what they were meant to be


def test_a_demand_inside_every_row_is_returned_unchanged() -> None:
    rng = np.random.default_rng(7)
    M, J, C, lo, hi, scale, _ = _problem(rng, True, True)
    a_d = np.zeros(N)
    lo, hi = np.minimum(lo, -1.0), np.maximum(hi, 1.0)
    a, status = solve_exact(np.linalg.inv(M), a_d, J, C, lo, hi, scale)
    assert status == QP_SOLVED and np.array_equal(a, a_d)


def test_repeated_rows_and_a_zero_width_box_are_solved() -> None:
    """Dependent normals (a row given twice) and lo == hi (the jerk and braking bands meeting)."""
    rng = np.random.default_rng(3)
    M, J, C, lo, hi, scale, a_d = _problem(rng, True, False)
    x = np.linalg.pinv(J) @ (J @ a_d)  # meets the task
    C2 = np.vstack([C, C[:2]])
    lo2, hi2 = np.concatenate([lo, lo[:2]]), np.concatenate([hi, hi[:2]])
    lo2[3] = hi2[3] = x[3]
    lo2 = np.minimum(lo2, C2 @ x)
    hi2 = np.maximum(hi2, C2 @ x)
    scale2 = np.concatenate([scale, scale[:2]])
    ref = _quadprog(M, J, C2, lo2, hi2, scale2, a_d)
    a, status = solve_exact(np.linalg.inv(M), a_d, J, C2, lo2, hi2, scale2)
    assert ref is not None and status == QP_SOLVED
    np.testing.assert_allclose(a, ref, atol=1e-7 * (1.0 + np.abs(ref).max()))


def test_dependent_task_rows_are_reported_not_solved() -> None:
    """Task rows that are not independent break the method's assumption: it says so (the caller then
    falls back to quadprog) instead of returning a wrong answer."""
    M = np.eye(N)
    J = np.vstack([np.ones(N), np.ones(N)])
    C = np.eye(N)
    a_d = np.full(N, 3.0)
    _, status = dual_active_set(np.linalg.inv(M), a_d, J, C, -np.ones(N), np.ones(N), np.full(N, 1e-7),
                                np.ones(N), 100)
    assert status in (QP_NUMERICAL, QP_INFEASIBLE)
