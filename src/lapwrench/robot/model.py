"""Pinocchio model of the arm with its laparoscope, and the per-tick kinematics snapshot.

:class:`Kinematics` is the "configuration" object every wrench source and task reads: one call to
Pinocchio per tick fills it (mass matrix, nonlinear effects, frame poses and the end-effector
Jacobian), so nothing downstream calls Pinocchio again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from lapwrench.jit import kernel
from lapwrench.robot.description import (
    FRAME_C,
    FRAME_E,
    FRAME_H,
    RobotKind,
    ScopeGeometry,
    build_urdf,
)
from lapwrench.robot.limits import JointLimits, franka_limits
from lapwrench.spatial import Mat, Vec


class Kinematics(NamedTuple):
    """Robot state and derived quantities at one instant, all in the base frame {B}.

    A named tuple of arrays, so the compiled maths (:mod:`lapwrench.jit`) reads it as it is.

    ``J_E`` is the geometric Jacobian of the {E} origin ordered ``[J_Ew; J_Ev]`` (eq 33).
    ``d_z`` is the scope axis (eq 16) and ``P`` the projector orthogonal to it (eq 17), both
    filled by :func:`scope_axis`.
    """

    q: Vec
    dq: Vec
    M: Mat
    nle: Vec
    gravity: Vec
    p_E: Vec
    R_E: Mat
    J_E: Mat
    p_H: Vec
    R_H: Mat
    p_C: Vec
    R_C: Mat
    d_z: Vec
    P: Mat

    @property
    def twist_E(self) -> Vec:
        """[angular; linear] velocity of {E} (eq 33)."""
        return self.J_E @ self.dq


@kernel
def scope_axis(R_E: Mat) -> tuple[Vec, Mat]:
    """Eqs (16)-(17): d_z = R_E I_z (the laparoscope direction) and P = I3 - d_z d_zᵀ."""
    d = R_E[:, 2].copy()
    return d, np.eye(3) - np.outer(d, d)


class KinematicTerms(NamedTuple):
    """What Pinocchio gives per tick, before :func:`assemble_kinematics` (frames' origins and rotations in
    {B}; ``M_upper`` has only its upper triangle filled; ``J`` is Pinocchio's ``[J_v; J_ω]`` of {E},
    LOCAL_WORLD_ALIGNED)."""

    q: Vec
    dq: Vec
    M_upper: Mat
    nle: Vec
    gravity: Vec
    p_E: Vec
    R_E: Mat
    p_H: Vec
    R_H: Mat
    p_C: Vec
    R_C: Mat
    J: Mat


@kernel
def symmetrised(A_upper: Mat) -> Mat:
    """The symmetric matrix whose upper triangle is that of ``A_upper`` (Pinocchio fills only that one)."""
    n = A_upper.shape[0]
    A = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            A[i, j] = A_upper[i, j] if i <= j else A_upper[j, i]
    return A


@kernel
def assemble_kinematics(
    q: Vec, dq: Vec, M_upper: Mat, nle: Vec, gravity: Vec, p_E: Vec, R_E: Mat, p_H: Vec, R_H: Mat,
    p_C: Vec, R_C: Mat, J: Mat,
) -> Kinematics:
    """The tick's :class:`Kinematics` from Pinocchio's terms: M symmetrised, J_E = [J_ω; J_v] (eq 33),
    the scope axis (eqs 16-17); every array copied."""
    n = q.shape[0]
    M = symmetrised(M_upper)
    J_E = np.empty((6, n))
    J_E[:3] = J[3:]
    J_E[3:] = J[:3]
    d_z, P = scope_axis(R_E)
    return Kinematics(
        q.copy(), dq.copy(), M, nle.copy(), gravity.copy(), p_E.copy(), R_E.copy(), J_E, p_H.copy(), R_H.copy(),
        p_C.copy(), R_C.copy(), d_z, P,
    )


class ScopeAxis(NamedTuple):
    """The scope axis at one configuration, in {B}: the fields of :class:`Kinematics` that
    :mod:`lapwrench.rcm.geometry`'s ``rcm_error`` and ``insertion_depth`` read (p_E in m)."""

    p_E: Vec
    d_z: Vec
    P: Mat


class RobotModel:
    """The 7-DoF arm (fingers removed) with a laparoscope on the flange, in Pinocchio."""

    def __init__(self, kind: RobotKind = "panda", scope: ScopeGeometry | None = None) -> None:
        self.kind: RobotKind = kind
        self.scope = scope or ScopeGeometry()
        self.urdf = build_urdf(kind, self.scope)
        self.model = pin.buildModelFromXML(self.urdf)
        self.data = self.model.createData()
        if self.model.nq != 7 or self.model.nv != 7:
            raise ValueError(f"expected a 7-DoF arm, the {kind} description has nq={self.model.nq}")
        self.nv = self.model.nv
        self.frame_E = self.model.getFrameId(FRAME_E)
        self.frame_H = self.model.getFrameId(FRAME_H)
        self.frame_C = self.model.getFrameId(FRAME_C)
        self.limits: JointLimits = franka_limits(kind, self.model)
        self._lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._axis_data = self.model.createData()  # scope_axis_at's own workspace

    @property
    def length(self) -> float:
        return self.scope.length

    def terms(self, q: Vec, dq: Vec) -> KinematicTerms:
        """Pinocchio at (q, dq): one ``computeAllTerms``, three frame placements and the {E} Jacobian,
        as C-contiguous float64 arrays (the types the compiled tick is bound to). They may share
        Pinocchio's memory: valid until the next call (:meth:`kinematics` copies them)."""
        model, data = self.model, self.data
        q = np.ascontiguousarray(q, dtype=np.float64)
        dq = np.ascontiguousarray(dq, dtype=np.float64)
        pin.computeAllTerms(model, data, q, dq)
        oE = pin.updateFramePlacement(model, data, self.frame_E)
        oH = pin.updateFramePlacement(model, data, self.frame_H)
        oC = pin.updateFramePlacement(model, data, self.frame_C)
        J = pin.getFrameJacobian(model, data, self.frame_E, self._lwa)
        c = np.ascontiguousarray
        return KinematicTerms(
            q, dq, c(data.M), c(data.nle), c(data.g), c(oE.translation), c(oE.rotation),
            c(oH.translation), c(oH.rotation), c(oC.translation), c(oC.rotation), c(J),
        )

    def kinematics(self, q: Vec, dq: Vec) -> Kinematics:
        """Evaluate the model at (q, dq) (:meth:`terms`, :func:`assemble_kinematics`)."""
        return assemble_kinematics(*self.terms(q, dq))

    def mass_matrix_inverse(self, q: Vec) -> Mat:
        """M(q)⁻¹ by Pinocchio's ABA-based ``computeMinverse`` (symmetrised)."""
        return symmetrised(np.ascontiguousarray(pin.computeMinverse(self.model, self.data, q)))

    def frame_pose(self, q: Vec, frame: str) -> pin.SE3:
        """Pose of a named frame at q (convenience, not for the control tick)."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.model.getFrameId(frame)].copy()

    def scope_axis_at(self, q: Vec) -> ScopeAxis:
        """The scope axis (eqs 16-17) at joints ``q``, e.g. the *measured* ones: one forward
        kinematics pass and the {E} placement (a few µs), on a workspace of its own so it never
        disturbs the tick's :meth:`kinematics`. Non-finite ``q`` gives non-finite values."""
        model, data = self.model, self._axis_data
        pin.forwardKinematics(model, data, np.asarray(q, dtype=float))
        oE = pin.updateFramePlacement(model, data, self.frame_E)
        d_z, P = scope_axis(np.ascontiguousarray(oE.rotation))
        return ScopeAxis(np.array(oE.translation, dtype=np.float64), d_z, P)
