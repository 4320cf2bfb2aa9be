"""Task/null-space allocation of the wrenches (eq 2-4, 37-38)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from lapwrench.spatial import Mat, Vec, Wrench


def weighted_pseudo_inverse(J: Mat, Minv: Mat, null_direction: Vec | None = None) -> Mat:
    """Eq (4): J⁺ = M⁻¹ Jᵀ (J M⁻¹ Jᵀ)⁻¹, the mass-matrix-weighted (dynamically consistent) inverse.

    If the task has a known null direction ``n`` (a unit vector with nᵀ J = 0, e.g. d_z for the
    lateral RCM task), J M⁻¹ Jᵀ is singular along it and its pseudo-inverse is computed exactly
    as (J M⁻¹ Jᵀ + n nᵀ)⁻¹ - n nᵀ.
    """
    A = J @ Minv @ J.T
    if null_direction is None:
        A_inv = np.linalg.inv(A)
    else:
        nn = np.outer(null_direction, null_direction)
        A_inv = np.linalg.inv(A + nn) - nn
    return Minv @ J.T @ A_inv


def nullspace_projector(J: Mat, J_pinv: Mat) -> Mat:
    """Eq (3): N = I_n - J⁺ J."""
    return np.eye(J.shape[1]) - J_pinv @ J


def nullspace_wrench(wrenches: Iterable[Wrench], p_G: Vec) -> Vec:
    """Eq (38): W_n = Q_h W_h + Q_c W_c + W_f, every wrench moved to p_G with its Q (eq 39)."""
    W_n = np.zeros(6)
    for w in wrenches:
        W_n += w.about(p_G)
    return W_n


def nullspace_torque(J_G: Mat, W_n: Vec) -> Vec:
    """Eq (37): τ_n = J_Gᵀ W_n."""
    return J_G.T @ W_n


def task_priority_torque(J_R: Mat, F_r: Vec, N_r: Mat, tau_n: Vec) -> Vec:
    """Eq (2): τ = J_Rᵀ F_r + N_rᵀ τ_n."""
    return J_R.T @ F_r + N_r.T @ tau_n
