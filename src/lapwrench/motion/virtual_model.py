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

from lapwrench.robot.model import Kinematics
from lapwrench.spatial import Mat, Vec


def self_motion_damping(kin: Kinematics, Minv: Mat, rate: float) -> Mat:
    """Damping matrix B_s of the arm's self-motion: τ_s = -B_s θ̇, B_s = d M N_E.

    The RCM task and the closest-point wrenches act through J_R and J_G, whose rows lie in the
    row space of J_E; the motion of the arm that leaves {E} still (self-motion, 1 DOF for the
    7-DoF arm) is therefore undamped and would drift. N_E = I - J_E⁺ J_E is the dynamically
    consistent null-space projector of J_E (J_E⁺ weighted by M, eq 4), so:

    - J_E M⁻¹ B_s = 0: the torque produces no acceleration of {E}, the scope is not disturbed;
    - θ̇ᵀ B_s θ̇ = d ‖N_E θ̇‖²_M >= 0: it only dissipates, at rate d (1/s).

    Computed as d (M - J_Eᵀ Λ_E J_E) with Λ_E = (J_E M⁻¹ J_Eᵀ)⁻¹, which equals d M N_E.
    """
    if rate == 0.0:
        return np.zeros_like(kin.M)
    J = kin.J_E
    A = J @ Minv @ J.T + 1e-9 * np.eye(6)
    return rate * (kin.M - J.T @ np.linalg.solve(A, J))


def euler_velocity_step(
    kin: Kinematics,
    tau: Vec,
    damping: Mat,
    dt: float,
    integrator: Literal["semi_implicit", "explicit"] = "semi_implicit",
) -> Vec:
    """One Euler step of the velocity: returns θ̇⁺ (the caller integrates θ⁺ = θ + dt θ̇⁺).

    ``tau`` is the full fused torque evaluated at the current θ̇ (it already contains -B θ̇);
    ``damping`` is B, the Jacobian of -τ with respect to θ̇.
    """
    rhs = dt * (tau - (kin.nle - kin.gravity))
    if integrator == "explicit":
        return kin.dq + np.linalg.solve(kin.M, rhs)
    return kin.dq + np.linalg.solve(kin.M + dt * damping, rhs)
