"""Pinocchio model of the arm with its laparoscope, and the per-tick kinematics snapshot.

:class:`Kinematics` is the "configuration" object every wrench source and task reads: one call to
Pinocchio per tick fills it (mass matrix, nonlinear effects, frame poses and the end-effector
Jacobian), so nothing downstream calls Pinocchio again.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin

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


@dataclass(frozen=True)
class Kinematics:
    """Robot state and derived quantities at one instant, all in the base frame {B}.

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


def scope_axis(R_E: Mat) -> tuple[Vec, Mat]:
    """Eqs (16)-(17): d_z = R_E I_z (the laparoscope direction) and P = I3 - d_z d_zᵀ."""
    d = R_E[:, 2].copy()
    return d, np.eye(3) - np.outer(d, d)


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
        self._lower = np.tril_indices(self.nv, -1)
        self._axis_data = self.model.createData()  # scope_axis_at's own workspace

    @property
    def length(self) -> float:
        return self.scope.length

    def kinematics(self, q: Vec, dq: Vec) -> Kinematics:
        """Evaluate the model at (q, dq): one ``computeAllTerms`` and three frame placements."""
        model, data = self.model, self.data
        pin.computeAllTerms(model, data, q, dq)
        M = data.M.copy()
        M[self._lower] = M.T[self._lower]  # Pinocchio fills the upper triangle only
        oE = pin.updateFramePlacement(model, data, self.frame_E)
        oH = pin.updateFramePlacement(model, data, self.frame_H)
        oC = pin.updateFramePlacement(model, data, self.frame_C)
        J = pin.getFrameJacobian(model, data, self.frame_E, self._lwa)
        J_E = np.vstack([J[3:], J[:3]])
        R_E = oE.rotation.copy()
        d_z, P = scope_axis(R_E)
        return Kinematics(
            q=np.array(q, dtype=float),
            dq=np.array(dq, dtype=float),
            M=M,
            nle=data.nle.copy(),
            gravity=data.g.copy(),
            p_E=oE.translation.copy(),
            R_E=R_E,
            J_E=J_E,
            p_H=oH.translation.copy(),
            R_H=oH.rotation.copy(),
            p_C=oC.translation.copy(),
            R_C=oC.rotation.copy(),
            d_z=d_z,
            P=P,
        )

    def mass_matrix_inverse(self, q: Vec) -> Mat:
        """M(q)⁻¹ by Pinocchio's ABA-based ``computeMinverse`` (symmetrised)."""
        Minv = pin.computeMinverse(self.model, self.data, q).copy()
        Minv[self._lower] = Minv.T[self._lower]
        return Minv

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
        d_z, P = scope_axis(oE.rotation)
        return ScopeAxis(oE.translation.copy(), d_z, P)
