"""Spatial algebra: the cross-product matrix, the wrench transform (eq 37-39), the Wrench value, and the
small linear algebra the compiled tick uses in place of BLAS/LAPACK calls."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.spatial import (
    Wrench,
    cholesky_factor,
    cholesky_inverse,
    cross3,
    inner,
    lu_solve,
    matvec,
    skew,
    wrench_transform,
)


@pytest.mark.parametrize("seed", range(5))
def test_wrench_transform_preserves_moment_about_any_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p_H, p_G, p_any = rng.standard_normal((3, 3))
    M, F = rng.standard_normal((2, 3))
    W_G = wrench_transform(p_H, p_G) @ np.concatenate([M, F])
    np.testing.assert_allclose(W_G[3:], F)
    # the moment about any point is the same whichever point the wrench was taken about
    np.testing.assert_allclose(W_G[:3] + np.cross(p_G - p_any, F), M + np.cross(p_H - p_any, F), atol=1e-12)


def test_skew_is_the_cross_product_matrix() -> None:
    rng = np.random.default_rng(7)
    for v, w in rng.standard_normal((10, 2, 3)):
        S = skew(v)
        np.testing.assert_allclose(S @ w, np.cross(v, w), atol=1e-12)
        np.testing.assert_array_equal(S, -S.T)


def test_a_wrench_is_moment_then_force_and_moves_its_moment_point() -> None:
    w = Wrench(np.array([0.0, 0.0, 0.5]), np.array([2.0, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(w.vector, [0.0, 0.0, 0.5, 2.0, 0.0, 0.0])  # [moment; force]
    # about a point 1 m up the y axis: the force's lever arm adds (0 - p) x F = (0, -1, 0) x (2, 0, 0)
    np.testing.assert_allclose(w.about(np.array([0.0, 1.0, 0.0])), [0.0, 0.0, 2.5, 2.0, 0.0, 0.0])
    np.testing.assert_allclose(w.about(w.point), w.vector)


def test_the_zero_wrench_keeps_its_point() -> None:
    z = Wrench.zero([0.1, 0.2, 0.3])
    assert not z.vector.any()
    np.testing.assert_array_equal(z.point, [0.1, 0.2, 0.3])
    assert z.point.dtype == np.float64


# -- the small linear algebra of the 1 kHz tick ------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 6, 7])
def test_cholesky_inverse_is_the_symmetric_inverse(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(5):
        B = rng.standard_normal((n, n))
        A = B @ B.T + 0.1 * np.eye(n)
        A_inv, ok = cholesky_inverse(A)
        assert ok
        np.testing.assert_array_equal(A_inv, A_inv.T)
        np.testing.assert_allclose(A_inv, np.linalg.inv(A), rtol=1e-10, atol=1e-12 * np.abs(A_inv).max())


@pytest.mark.parametrize("A", [np.diag([1.0, 0.0, 2.0]), np.diag([1.0, -1.0]), np.full((2, 2), np.nan)],
                         ids=["singular", "indefinite", "nan"])
def test_cholesky_inverse_refuses_a_matrix_that_is_not_positive_definite(A: np.ndarray) -> None:
    A_inv, ok = cholesky_inverse(A)
    assert not ok and not A_inv.any()


@pytest.mark.parametrize("n", [1, 3, 7])
def test_lu_solve_solves_with_pivoting(n: int) -> None:
    rng = np.random.default_rng(10 + n)
    for _ in range(5):
        A, b = rng.standard_normal((n, n)), rng.standard_normal(n)
        x, ok = lu_solve(A, b)
        assert ok
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)
    P = np.array([[0.0, 1.0], [1.0, 0.0]])  # a zero first pivot: needs the row exchange
    x, ok = lu_solve(P, np.array([2.0, 3.0]))
    assert ok
    np.testing.assert_allclose(x, [3.0, 2.0])


def test_lu_solve_reports_a_singular_system_with_nans() -> None:
    x, ok = lu_solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.array([1.0, 1.0]))
    assert not ok and np.isnan(x).all()


def test_cholesky_factor_writes_l_into_a_larger_workspace_and_honours_its_tolerance() -> None:
    A = np.array([[4.0, 2.0], [2.0, 3.0]])
    L = np.full((3, 3), 7.0)
    assert cholesky_factor(A, L, 0.0)
    np.testing.assert_allclose(np.tril(L[:2, :2]) @ np.tril(L[:2, :2]).T, A, rtol=1e-14)
    assert L[2, 2] == 7.0  # outside the q x q block: untouched
    nearly_singular = np.array([[1.0, 1.0], [1.0, 1.0 + 1e-15]])
    assert cholesky_factor(nearly_singular, np.zeros((2, 2)), 0.0)
    assert not cholesky_factor(nearly_singular, np.zeros((2, 2)), 1e-14)


def test_matvec_inner_and_cross3_are_numpys() -> None:
    rng = np.random.default_rng(4)
    A, x, a, b = rng.standard_normal((6, 7)), rng.standard_normal(7), rng.standard_normal(3), rng.standard_normal(3)
    np.testing.assert_allclose(matvec(A, x), A @ x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(matvec(A.T, A[:, 0]), A.T @ A[:, 0], rtol=1e-12, atol=1e-14)  # strided views
    assert inner(x, x) == pytest.approx(x @ x, rel=1e-14)
    np.testing.assert_allclose(cross3(a, b), np.cross(a, b), rtol=1e-14, atol=1e-15)
