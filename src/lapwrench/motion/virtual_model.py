"""The gravity-compensated virtual model integrated into joint position references.

The paper drives a model of the arm with the fused torque and Euler-integrates it at 1 kHz
into the references sent to the Franka (Sec. IV). The model is eq (1) with gravity compensated:

    M(θ) θ̈ + C(θ, θ̇) θ̇ = τ.

Integrator choice (``motion.integrator``):

- ``explicit``: the printed Euler step, θ̇⁺ = θ̇ + dt M⁻¹ (τ - C θ̇), θ⁺ = θ + dt θ̇⁺.
- ``semi_implicit`` (default): the velocity-proportional terms -B θ̇ of τ (the viscous wrench
  eq 40, K_d of eq 14, the self-motion damping) are taken at θ̇⁺:
  (M + dt B)(θ̇⁺ - θ̇) = dt (τ - C θ̇). With the paper's k_t = 150 N m s and the wrist's
  rotational inertia of order 10⁻² kg m², dt·k_t/I ≈ 15 ≫ 2, so the explicit step is unstable at
  1 kHz; the semi-implicit step is unconditionally stable for damping and identical otherwise.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from lapwrench.allocation import nullspace_projector, weighted_pseudo_inverse
from lapwrench.jit import kernel_inlined
from lapwrench.robot.model import Kinematics
from lapwrench.spatial import Mat, Vec, lu_solve_in_place, matmul

Integrator = Literal["semi_implicit", "explicit"]  # motion.integrator


@kernel_inlined
def self_motion_projector(kin: Kinematics, Minv: Mat) -> Mat:
    """N_Eᵀ = I - J_Eᵀ Λ_E J_E M⁻¹, Λ_E = (J_E M⁻¹ J_Eᵀ)⁻¹: keeps the part of a torque that leaves {E} still.

    N_E = I - J_E⁺ J_E is the dynamically consistent null-space projector of J_E (eq 3, with J_E⁺
    the M-weighted inverse of eq 4, :func:`~lapwrench.allocation.weighted_pseudo_inverse`), so
    J_E M⁻¹ N_Eᵀ τ = 0 for every τ: the projected torque moves only the arm's self-motion (1 DOF
    for the 7-DoF arm), never the scope. Near a singularity of J_E the inverse is damped
    (:func:`~lapwrench.allocation.regularised_inverse`).
    """
    J = kin.J_E
    # eq (3) with the transposed factors, I - J_Eᵀ J_E⁺ᵀ = (I - J_E⁺ J_E)ᵀ, the same products summed in the
    # same order: N_Eᵀ without a transposed copy
    return nullspace_projector(weighted_pseudo_inverse(J, Minv).T, J.T)


@kernel_inlined
def self_motion_damping(kin: Kinematics, N_E_T: Mat, rate: float) -> Mat:
    """Damping matrix B_s of the arm's self-motion: τ_s = -B_s θ̇, B_s = d N_Eᵀ M = d M N_E.

    The RCM task and the closest-point wrenches act through J_R and J_G, whose rows lie in the
    row space of J_E; the self-motion is therefore undamped and would drift. With ``N_E_T`` from
    :func:`self_motion_projector`:

    - J_E M⁻¹ B_s = 0: the torque produces no acceleration of {E}, the scope is not disturbed;
    - θ̇ᵀ B_s θ̇ = d ‖N_E θ̇‖²_M >= 0: it only dissipates, at rate d (1/s).
    """
    if rate == 0.0:
        return np.zeros_like(kin.M)
    return matmul(N_E_T, kin.M, rate)  # (d N_Eᵀ) M


@kernel_inlined
def add_self_motion_torque(tau: Vec, N_E_T: Mat, push: Vec, B_self: Mat, dq: Vec) -> None:
    """τ += N_Eᵀ τ_push - B_s θ̇ in place: a torque through the self-motion projector (e.g. the joint-limit
    push, :func:`joint_limit_torque`) and the self-motion damping (:func:`self_motion_damping`)."""
    n = tau.shape[0]
    for i in range(n):
        pushed, damped = 0.0, 0.0
        for k in range(n):
            pushed += N_E_T[i, k] * push[k]
            damped += B_self[i, k] * dq[k]
        tau[i] = tau[i] + pushed - damped


@kernel_inlined
def damping_jacobian(J_R: Mat, Kd: float, N_r: Mat, J_G: Mat, D: Mat, B_self: Mat) -> Mat:
    """B = J_Rᵀ K_d J_R + N_rᵀ J_Gᵀ D J_G + B_s: the θ̇-Jacobian of -τ, for the semi-implicit step.

    The terms are eq (14)'s K_d ė_R through J_R (eq 2), the damping sources' -D J_G θ̇ (eq 40)
    through the null space (eq 2, 37) and the self-motion damping B_s.
    """
    B = matmul(J_R.T, J_R, Kd)  # (K_d J_Rᵀ) J_R
    null = matmul(N_r.T, matmul(J_G.T, matmul(D, J_G)))
    for i in range(B.shape[0]):
        for j in range(B.shape[1]):
            B[i, j] = B[i, j] + null[i, j] + B_self[i, j]
    return B


@kernel_inlined
def joint_limit_torque(q: Vec, lower: Vec, upper: Vec, zone: float, stiffness: float) -> Vec:
    """-k ∇H(q), H = ½ Σ_i (distance of q_i into the ``zone`` next to either limit)²: a push away
    from each joint limit that is zero outside the zone and grows linearly inside it (N m).

    The controller applies it through :func:`self_motion_projector`, so the redundant self-motion
    keeps the joints away from their limits without moving the scope.
    """
    n = q.shape[0]
    tau = np.empty(n)
    for i in range(n):
        tau[i] = stiffness * (np.maximum(lower[i] + zone - q[i], 0.0) - np.maximum(q[i] - (upper[i] - zone), 0.0))
    return tau


@kernel_inlined
def euler_velocity_step(
    kin: Kinematics,
    tau: Vec,
    damping: Mat,
    dt: float,
    integrator: Integrator = "semi_implicit",
) -> Vec:
    """One Euler step of the velocity: returns θ̇⁺ (the caller integrates θ⁺ = θ + dt θ̇⁺).

    ``tau`` is the full fused torque evaluated at the current θ̇ (it already contains -B θ̇);
    ``damping`` is B, the Jacobian of -τ with respect to θ̇. The n x n system is solved by
    :func:`~lapwrench.spatial.lu_solve_in_place` (partial pivoting, as LAPACK's, without its call cost); a
    singular system gives NaNs, which the tick treats as a non-finite demand (it brakes).
    """
    n = tau.shape[0]
    rhs = np.empty(n)
    for i in range(n):
        rhs[i] = dt * (tau[i] - (kin.nle[i] - kin.gravity[i]))
    A = np.empty((n, n))  # M, or M + dt B
    explicit = integrator == "explicit"  # compared once: a string comparison per element cost 1-2 µs a tick
    for i in range(n):
        for j in range(n):
            A[i, j] = kin.M[i, j] if explicit else kin.M[i, j] + dt * damping[i, j]
    lu_solve_in_place(A, rhs)  # rhs becomes the step
    for i in range(n):
        rhs[i] += kin.dq[i]
    return rhs
