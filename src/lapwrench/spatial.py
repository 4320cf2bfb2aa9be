"""Spatial algebra shared by all wrench sources.

Conventions (paper Sec. III): a wrench is ``[moment; force]`` and a geometric Jacobian maps joint
rates to ``[angular velocity; linear velocity]``, both expressed in the base frame {B}. A wrench is
always attached to a reference point (the point its moment is taken about).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lapwrench.jit import kernel

Vec = NDArray[np.float64]
Mat = NDArray[np.float64]


@kernel
def skew(v: Vec) -> Mat:
    """[v]x such that [v]x w = v x w."""
    S = np.zeros((3, 3))
    S[0, 1], S[0, 2] = -v[2], v[1]
    S[1, 0], S[1, 2] = v[2], -v[0]
    S[2, 0], S[2, 1] = -v[1], v[0]
    return S


@kernel
def wrench_transform(p_from: Vec, p_to: Vec) -> Mat:
    """Eq (39): Q moves a wrench taken about ``p_from`` to the equivalent wrench about ``p_to``.

        Q = [[I3, [p_from - p_to]x],
             [0,  I3             ]]

    so that M_to = M_from + (p_from - p_to) x F and F is unchanged, in the base frame.
    """
    Q = np.eye(6)
    Q[:3, 3:] = skew(p_from - p_to)
    return Q


@kernel
def cross3(a: Vec, b: Vec) -> Vec:
    """a x b for two 3-vectors, written out (numba's ``np.cross`` broadcasts and costs twice as much)."""
    out = np.empty(3)
    cross3_into(a, b, out)
    return out


@kernel
def cross3_into(a: Vec, b: Vec, out: Vec) -> None:
    """out = a x b (:func:`cross3`) written into ``out``, which must not share memory with ``a`` or ``b``."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@kernel
def matvec(A: Mat, x: Vec) -> Vec:
    """A x, in a loop: numba's ``@`` calls BLAS, whose call costs more than the arithmetic for the
    tick's small matrices (0.3 µs against 0.05 µs for 3 x 3)."""
    y = np.empty(A.shape[0])
    matvec_into(A, x, y)
    return y


@kernel
def matvec_into(A: Mat, x: Vec, y: Vec) -> None:
    """y = A x (:func:`matvec`) written into ``y``, which must not share memory with ``x``."""
    m, n = A.shape
    for i in range(m):
        acc = 0.0
        for j in range(n):
            acc += A[i, j] * x[j]
        y[i] = acc


@kernel
def matmul(A: Mat, B: Mat, scale: float = 1.0) -> Mat:
    """(scale A) B, in loops: for the tick's small matrices numba's ``@`` (a BLAS call, its output and,
    for a transposed operand, a contiguous copy) costs more than the arithmetic. Pass transposes as
    views (``A.T``). Each element is summed in the order of the inner index, row by row, so the
    loops stay independent (no chain of dependent additions)."""
    m, k = A.shape
    n = B.shape[1]
    C = np.zeros((m, n))
    for i in range(m):
        for p in range(k):
            a = scale * A[i, p]
            for j in range(n):
                C[i, j] += a * B[p, j]
    return C


@kernel
def all_finite(x: Vec) -> bool:
    """Every element of the vector ``x`` is a number (``np.isfinite(x).all()`` without its temporary array)."""
    for i in range(x.shape[0]):  # noqa: SIM110 (a loop: numba's all() of a generator is slower)
        if not math.isfinite(x[i]):
            return False
    return True


@kernel
def inner(a: Vec, b: Vec) -> float:
    """aᵀ b, in a loop (numba's ``@`` of two vectors is a BLAS call too)."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


# -- small dense linear algebra for the 1 kHz tick ----------------------------------------------------
# numba calls LAPACK for np.linalg.inv / solve with copies to Fortran order and a workspace query:
# 1-2 µs for the tick's 2 x 2 to 7 x 7 matrices. These loops give the same results (to round-off) in
# a fraction of that.


@kernel
def cholesky_factor(A: Mat, L: Mat, rel_tol: float) -> bool:
    """A = L Lᵀ for a symmetric positive definite A (q x q, its lower triangle is read), L written into
    the top-left q x q of ``L`` (lower triangle; a workspace at least that large).

    False when a pivot is not above ``rel_tol`` x max(1, |A_jj|): A is not (numerically) positive
    definite, singular, or not a number.
    """
    q = A.shape[0]
    for j in range(q):
        d = A[j, j]
        for c in range(j):
            d -= L[j, c] * L[j, c]
        if not d > rel_tol * max(1.0, abs(A[j, j])):
            return False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, q):
            v = A[i, j]
            for c in range(j):
                v -= L[i, c] * L[j, c]
            L[i, j] = v / L[j, j]
    return True


@kernel
def cholesky_inverse(A: Mat) -> tuple[Mat, bool]:
    """A⁻¹ of a symmetric positive definite A (its lower triangle is read) through A = L Lᵀ, A⁻¹ = L⁻ᵀ L⁻¹.

    Returns (A⁻¹, True), or (zeros, False) when a pivot is not positive (:func:`cholesky_factor`).
    The result is exactly symmetric.
    """
    n = A.shape[0]
    work = np.zeros((2, n, n))  # L and X = L⁻¹ (lower triangular) in one allocation
    L, X = work[0], work[1]
    if not cholesky_factor(A, L, 0.0):
        return np.zeros((n, n)), False
    for j in range(n):
        X[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            v = 0.0
            for c in range(j, i):
                v -= L[i, c] * X[c, j]
            X[i, j] = v / L[i, i]
    out = np.empty((n, n))  # Xᵀ X
    for i in range(n):
        for j in range(i, n):
            v = 0.0
            for c in range(j, n):
                v += X[c, i] * X[c, j]
            out[i, j] = v
            out[j, i] = v
    return out, True


@kernel
def lu_solve(A: Mat, b: Vec) -> tuple[Vec, bool]:
    """x with A x = b, by Gaussian elimination with partial pivoting (what LAPACK's gesv does).

    Returns (x, True), or (NaNs, False) when a pivot is exactly zero (A singular).
    """
    x = b.copy()
    return x, lu_solve_in_place(A.copy(), x)


@kernel
def lu_solve_in_place(U: Mat, x: Vec) -> bool:
    """:func:`lu_solve` overwriting its arguments: ``U`` (A on entry) with its eliminated form, ``x``
    (b on entry) with the solution (NaNs and False when a pivot is exactly zero)."""
    n = U.shape[0]
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(U[i, k]) > abs(U[p, k]):
                p = i
        if U[p, k] == 0.0:
            x[:] = np.nan
            return False
        if p != k:
            for c in range(k, n):
                U[k, c], U[p, c] = U[p, c], U[k, c]
            x[k], x[p] = x[p], x[k]
        for i in range(k + 1, n):
            f = U[i, k] / U[k, k]
            for c in range(k + 1, n):
                U[i, c] -= f * U[k, c]
            x[i] -= f * x[k]
    for i in range(n - 1, -1, -1):
        v = x[i]
        for c in range(i + 1, n):
            v -= U[i, c] * x[c]
        x[i] = v / U[i, i]
    return True


@dataclass(frozen=True)
class Wrench:
    """A wrench ``[moment; force]`` in {B}, with the moment taken about ``point``."""

    moment: Vec
    force: Vec
    point: Vec

    @staticmethod
    def zero(point: Vec) -> Wrench:
        return Wrench(np.zeros(3), np.zeros(3), np.asarray(point, dtype=float))

    @property
    def vector(self) -> Vec:
        return np.concatenate([self.moment, self.force])

    def about(self, point: Vec) -> Vec:
        """The 6-vector of the same wrench taken about ``point`` (eq 39)."""
        return wrench_transform(self.point, point) @ self.vector
