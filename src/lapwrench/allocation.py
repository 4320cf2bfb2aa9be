"""Task/null-space allocation of the wrenches (eq 2-4, 37-38)."""

from __future__ import annotations

import math

import numpy as np

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.spatial import Mat, Vec, all_finite, cholesky_inverse, matmul, matvec

# Eigenvalues of J M⁻¹ Jᵀ below this fraction of the largest are damped (see ``regularised_inverse``).
RCOND = 1e-10
# Below this Frobenius condition number ``regularised_inverse`` keeps the Cholesky inverse: it then agrees with
# LAPACK's LU inverse to about 1e-10 relative (round-off times the condition number).
CHOLESKY_CONDITION = 1e5


@kernel
def weighted_pseudo_inverse(J: Mat, Minv: Mat, null_direction: Vec | None = None, rcond: float = RCOND) -> Mat:
    """Eq (4): J⁺ = M⁻¹ Jᵀ (J M⁻¹ Jᵀ)⁻¹, the mass-matrix-weighted (dynamically consistent) inverse.

    If the task has a known null direction ``n`` (a unit vector with nᵀ J = 0, e.g. d_z for the
    lateral RCM task), J M⁻¹ Jᵀ is singular along it and its pseudo-inverse is computed exactly
    as (J M⁻¹ Jᵀ + n nᵀ)⁻¹ - n nᵀ (J M⁻¹ Jᵀ + n nᵀ is positive definite: inverted by its Cholesky
    factor; should round-off say otherwise, by :func:`regularised_inverse`).

    Without one, (J M⁻¹ Jᵀ)⁻¹ is :func:`regularised_inverse`: the printed inverse whenever
    J M⁻¹ Jᵀ is well conditioned (smallest eigenvalue >= ``rcond`` x the largest), a damped one
    otherwise. The printed RCM task (eq 28) needs it: its J_R has rank 2 at e_R = 0, where
    d_zᵀ J_R = -(d_z x e_R)ᵀ J_Eω vanishes, and the smallest eigenvalue of J_R M⁻¹ J_Rᵀ scales as
    |e_R|² (about 1e-10 of the largest at |e_R| = 10 µm).

    J M⁻¹ is formed once: J M⁻¹ Jᵀ is (J M⁻¹) Jᵀ, evaluated in the printed order (near the damping
    threshold A's condition number reaches 1e10, and another order of the products, or another
    rounding of them, moves A⁻¹ by 1e-7), and M⁻¹ Jᵀ is its transpose (M⁻¹ is symmetric).
    """
    m = J.shape[0]
    if null_direction is None:
        # BLAS, as numpy's printed formula: near the damping threshold A's condition number reaches 1e10, and
        # only the same rounding of J M⁻¹ and (J M⁻¹) Jᵀ gives the printed A⁻¹ to 1e-9
        JM = J @ Minv
        A_inv = regularised_inverse(JM @ np.ascontiguousarray(J.T), rcond)
    else:
        # (J M⁻¹) Jᵀ + n nᵀ is well conditioned: loops, without BLAS's call cost
        JM = matmul(J, Minv)
        A = matmul(JM, J.T)
        nd = null_direction
        for i in range(m):
            for j in range(m):
                A[i, j] += nd[i] * nd[j]  # A + n nᵀ
        A_inv, ok = cholesky_inverse(A)
        if not ok:
            A_inv = regularised_inverse(A, rcond)
        for i in range(m):
            for j in range(m):
                A_inv[i, j] -= nd[i] * nd[j]
    J_pinv = matmul(JM.T, A_inv)  # (J M⁻¹)ᵀ A⁻¹
    return J_pinv


@kernel
def regularised_inverse(A: Mat, rcond: float = RCOND) -> Mat:
    """Inverse of a symmetric positive semi-definite A, damped along its near-null eigenvectors.

    With A = U diag(λ) Uᵀ and δ = ``rcond`` λ_max, each eigenvalue is inverted as

        f(λ) = 1/λ          λ >= δ
        f(λ) = λ / δ²       λ <  δ     (damped least squares λ / (λ² + μ²) with μ² = δ² - λ²)

    f is continuous at δ, and f(0) = 0: at an exact singularity A⁻¹ is replaced by the
    Moore-Penrose pseudo-inverse, so J⁺ J stays the M-orthogonal projector on the rows of J that
    are left. A = 0 gives 0. When the Frobenius condition number ‖A‖ ‖A⁻¹‖ (>= λ_max / λ_min)
    is at most 1/``rcond``, every λ >= δ and A⁻¹ is returned as ``inv(A)``, the printed formula.
    (LAPACK's LU, like numpy's ``inv``, not a Cholesky factor: near the damping threshold the
    condition number reaches 1e10, and only the same algorithm gives the printed formula's value
    to 1e-9 there. Below :data:`CHOLESKY_CONDITION`, where both agree to round-off, the cheaper
    Cholesky inverse is kept.)

    A non-finite A gives a NaN matrix (for the tick's non-finite guard), never an exception.
    """
    if not all_finite(A.ravel()):
        return np.full(A.shape, np.nan)
    A_inv, ok = cholesky_inverse(A)
    if ok and _frobenius_condition(A, A_inv) <= CHOLESKY_CONDITION:
        return A_inv  # well conditioned: Cholesky and LU agree to round-off, the factor is cheaper
    try:
        A_inv = np.linalg.inv(A)  # type: ignore[assignment]  # float64 in and out; numpy's stubs: "floating"
    except Exception:  # singular (numpy's LinAlgError; numba raises its own)
        return _damped_inverse(A, rcond)
    if rcond * _frobenius_condition(A, A_inv) <= 1.0:  # False on inf/nan
        return A_inv
    return _damped_inverse(A, rcond)


@kernel
def _frobenius_condition(A: Mat, A_inv: Mat) -> float:
    """‖A‖ ‖A⁻¹‖ in the Frobenius norm (>= λ_max / λ_min for a symmetric A)."""
    norm2, inv_norm2 = 0.0, 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            norm2 += A[i, j] * A[i, j]
            inv_norm2 += A_inv[i, j] * A_inv[i, j]
    return math.sqrt(norm2 * inv_norm2)


@kernel
def _damped_inverse(A: Mat, rcond: float) -> Mat:
    """U diag(f(λ)) Uᵀ with f of :func:`regularised_inverse`."""
    lam, U = np.linalg.eigh(A)
    if not lam[-1] > 0.0:
        return np.zeros_like(A)
    delta = rcond * lam[-1]
    lam_c = np.maximum(lam, 0.0)
    f = np.where(lam_c >= delta, 1.0 / np.maximum(lam_c, delta), lam_c / delta**2)
    return (U * f) @ U.T


@kernel
def nullspace_projector(J: Mat, J_pinv: Mat) -> Mat:
    """Eq (3): N = I_n - J⁺ J."""
    N = matmul(J_pinv, J)
    for i in range(N.shape[0]):
        for j in range(N.shape[1]):
            N[i, j] = (1.0 if i == j else 0.0) - N[i, j]
    return N


@kernel_inlined
def nullspace_wrench(W: Mat, points: Mat, p_G: Vec) -> Vec:
    """Eq (38): W_n = Q_h W_h + Q_c W_c + W_f, every wrench moved to p_G with its Q (eq 39).

    ``W`` holds one wrench ``[moment; force]`` per row, taken about the point in the same row of
    ``points``. With Q of eq (39), Q_i W_i = [m_i + (p_i - p_G) x f_i; f_i].
    """
    W_n = np.zeros(6)
    for i in range(W.shape[0]):
        r0, r1, r2 = points[i, 0] - p_G[0], points[i, 1] - p_G[1], points[i, 2] - p_G[2]
        f0, f1, f2 = W[i, 3], W[i, 4], W[i, 5]
        W_n[0] += W[i, 0] + r1 * f2 - r2 * f1
        W_n[1] += W[i, 1] + r2 * f0 - r0 * f2
        W_n[2] += W[i, 2] + r0 * f1 - r1 * f0
        W_n[3] += f0
        W_n[4] += f1
        W_n[5] += f2
    return W_n


@kernel_inlined
def nullspace_torque(J_G: Mat, W_n: Vec) -> Vec:
    """Eq (37): τ_n = J_Gᵀ W_n."""
    return matvec(J_G.T, W_n)


@kernel_inlined
def task_priority_torque(J_R: Mat, F_r: Vec, N_r: Mat, tau_n: Vec) -> Vec:
    """Eq (2): τ = J_Rᵀ F_r + N_rᵀ τ_n."""
    n = J_R.shape[1]
    tau = np.empty(n)
    for i in range(n):
        a = 0.0
        for k in range(J_R.shape[0]):
            a += J_R[k, i] * F_r[k]
        b = 0.0
        for k in range(n):
            b += N_r[k, i] * tau_n[k]
        tau[i] = a + b
    return tau
