"""RCM task geometry: initial point, error, Jacobian, closest point and its Jacobian.

All quantities are in the base frame {B}; ``kin`` is the tick's :class:`Kinematics`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.robot.model import Kinematics, ScopeAxis
from lapwrench.spatial import Mat, Vec, cross3, inner, matmul, matvec, skew


class TaskGeometry(NamedTuple):
    """RCM and closest-point quantities of one tick (eq 27-36)."""

    p_R: Vec
    rcm_velocity: Vec
    e_R: Vec
    e_R_rate: Vec
    J_R: Mat
    s_star: float
    p_G: Vec
    o_G: Vec
    J_G: Mat
    e_R_offset: Vec  # measured minus reference e_R (m), filtered


@kernel
def initial_rcm_point(kin: Kinematics | ScopeAxis, length: float, lambda0: float) -> Vec:
    """Eq (18): p_R(t0) = p_E(θ0) + λ0 L d_z(θ0) (reads only ``kin.p_E`` and ``kin.d_z``)."""
    return kin.p_E + lambda0 * length * kin.d_z


@kernel_inlined
def rcm_error(kin: Kinematics | ScopeAxis, p_R: Vec) -> Vec:
    """Eq (27): e_R = P(θ) (p_R - p_E(θ)), the lateral offset of p_R from the scope axis."""
    P, p_E = kin.P, kin.p_E
    e = np.empty(3)
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += P[i, j] * (p_R[j] - p_E[j])
        e[i] = acc
    return e


@kernel
def insertion_depth(kin: Kinematics | ScopeAxis, p_R: Vec, length: float) -> float:
    """Depth (m) of the scope tip beyond p_R along the shaft: L - d_zᵀ (p_R - p_E) (tip at p_E + L d_z)."""
    return length - _axial(kin, p_R)


@kernel
def _axial(kin: Kinematics | ScopeAxis, p_R: Vec) -> float:
    """d_zᵀ (p_R - p_E): how far p_R lies along the shaft from p_E (no temporary arrays)."""
    d, p_E = kin.d_z, kin.p_E
    acc = 0.0
    for i in range(3):
        acc += d[i] * (p_R[i] - p_E[i])
    return acc


@kernel
def axis_rcm_error_and_depth(p_E: Vec, d_z: Vec, P: Mat, p_R: Vec, length: float) -> tuple[float, float]:
    """|e_R| (eq 27) and the tip depth beyond p_R for a scope axis given by its arrays (e.g. at the
    measured joints): array arguments only, so the call from Python is cheap."""
    axis = ScopeAxis(p_E, d_z, P)
    e = rcm_error(axis, p_R)
    return math.sqrt(inner(e, e)), insertion_depth(axis, p_R, length)


@kernel_inlined
def rcm_jacobian(kin: Kinematics, p_R: Vec) -> Mat:
    """Eq (28): J_R = ∂e_R/∂θ (3 x n), analytic.

    With r = p_R - p_E and ḋ_z = ω x d_z = -[d_z]x J_Eω θ̇, differentiating eq (27) gives

        J_R = ((d_zᵀ r) [d_z]x + d_z rᵀ [d_z]x) J_Eω - P J_Ev.

    Its rows satisfy d_zᵀ ė_R = -ḋ_zᵀ e_R, so J_R has rank 2 when e_R = 0 (see
    :func:`lateral_rcm_jacobian`).
    """
    d = kin.d_z
    r = p_R - kin.p_E
    Sd = skew(d)
    J_w = np.ascontiguousarray(kin.J_E[:3])
    J_v = np.ascontiguousarray(kin.J_E[3:])
    return ((d @ r) * Sd + np.outer(d, r @ Sd)) @ J_w - kin.P @ J_v


@kernel_inlined
def lateral_rcm_jacobian(kin: Kinematics, p_R: Vec) -> Mat:
    """P J_R = (d_zᵀ r) [d_z]x J_Eω - P J_Ev: the RCM Jacobian restricted to the lateral plane.

    e_R always lies in the plane orthogonal to d_z, so only two of its three rates are
    independent. Eq (4) inverts J_R M⁻¹ J_Rᵀ, which is singular when e_R = 0 and nearly singular
    near it (its third eigenvalue scales with |e_R|²). The lateral form has the exact null
    direction d_z at every configuration, so its pseudo-inverse is exact and well conditioned.
    """
    S = skew(kin.d_z)
    c = _axial(kin, p_R)  # d_zᵀ r
    J_E, P = kin.J_E, kin.P
    n = J_E.shape[1]
    J = np.empty((3, n))
    for i in range(3):
        for j in range(n):
            rot, lin = 0.0, 0.0
            for k in range(3):
                rot += (c * S[i, k]) * J_E[k, j]
                lin += P[i, k] * J_E[k + 3, j]
            J[i, j] = rot - lin
    return J


@kernel_inlined
def lateral_task(R_E: Mat, J_R: Mat) -> Mat:
    """The lateral RCM task J = [x_E  y_E]ᵀ J_R (2 x n): the RCM error's two rates across the shaft."""
    return matmul(R_E[:, :2].T, J_R)


@kernel_inlined
def rcm_error_rate(kin: Kinematics, J_R: Mat, rcm_velocity: Vec) -> Vec:
    """ė_R = J_R θ̇ + P ṗ_R: the joint-motion part (eq 28) plus the motion of the adaptive point."""
    rate = matvec(J_R, kin.dq)
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += kin.P[i, j] * rcm_velocity[j]
        rate[i] += acc
    return rate


@kernel_inlined
def rcm_error_drift(kin: Kinematics, p_R: Vec, rcm_velocity: Vec) -> Vec:
    """ë_R when θ̈ = 0 and p̈_R = 0: the velocity-product part of the RCM error's acceleration,
    ë_R = J_R θ̈ + (this), which eq (2) leaves uncompensated (:func:`lapwrench.wrenches.rcm.rcm_feedforward`).

    With r = p_R - p_E, c = d_zᵀ r and e_R = r - c d_z (eq 27), ω, v the twist J_E θ̇ of {E} (eq 33)
    and α, a its acceleration at θ̈ = 0 (``kin.a_E``):

        ḋ_z = ω x d_z,  d̈_z = α x d_z + ω x ḋ_z,  ṙ = ṗ_R - v,  r̈ = -a,
        ċ = ḋ_zᵀ r + d_zᵀ ṙ,  c̈ = d̈_zᵀ r + 2 ḋ_zᵀ ṙ + d_zᵀ r̈,
        ë_R = r̈ - c̈ d_z - 2 ċ ḋ_z - c d̈_z.
    """
    d = kin.d_z
    twist = matvec(kin.J_E, kin.dq)
    w, v = twist[:3], twist[3:]
    alpha, a = kin.a_E[:3], kin.a_E[3:]
    r = p_R - kin.p_E
    r_dot = rcm_velocity - v
    d_dot = cross3(w, d)  # np.cross's formula, without its temporaries (three arrays a call in numba)
    d_ddot = cross3(alpha, d)
    w_x_d_dot = cross3(w, d_dot)
    for i in range(3):
        d_ddot[i] += w_x_d_dot[i]  # α x d + ω x ḋ
    c = inner(d, r)
    c_dot = inner(d_dot, r) + inner(d, r_dot)
    c_ddot = inner(d_ddot, r) + 2.0 * inner(d_dot, r_dot) - inner(d, a)
    drift = np.empty(3)
    for i in range(3):
        drift[i] = -a[i] - c_ddot * d[i] - 2.0 * c_dot * d_dot[i] - c * d_ddot[i]
    return drift


@kernel_inlined
def closest_point_parameter(kin: Kinematics | ScopeAxis, p_R: Vec, length: float) -> float:
    """Eqs (29)-(30): s = d_zᵀ (p_R - p_E) / L, clamped to [0, 1]."""
    s = _axial(kin, p_R) / length
    return min(1.0, max(0.0, s))


@kernel_inlined
def closest_point(kin: Kinematics | ScopeAxis, s_star: float, length: float) -> tuple[Vec, Vec]:
    """Eqs (31)-(32): p_G = p_E + s* L d_z and its offset o_G = s* L d_z."""
    o_G = s_star * length * kin.d_z
    return kin.p_E + o_G, o_G


@kernel_inlined
def closest_point_jacobian(kin: Kinematics, o_G: Vec) -> Mat:
    """Eqs (34)-(36): J_G = [J_Eω; J_Ev - [o_G]x J_Eω] with s* frozen (6 x n)."""
    S = skew(o_G)
    J_E = kin.J_E
    n = J_E.shape[1]
    J_G = np.empty((6, n))
    for j in range(n):
        for i in range(3):
            J_G[i, j] = J_E[i, j]
    for i in range(3):
        for j in range(n):
            acc = 0.0
            for k in range(3):
                acc += S[i, k] * J_E[k, j]
            J_G[i + 3, j] = J_E[i + 3, j] - acc
    return J_G
