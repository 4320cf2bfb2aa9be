"""Pinocchio model of the arm with its laparoscope, and the per-tick kinematics snapshot.

:class:`Kinematics` is the "configuration" object every wrench source and task reads: one call to
Pinocchio per tick fills it (mass matrix, nonlinear effects, frame poses and the end-effector
Jacobian), so nothing downstream calls Pinocchio again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from lapwrench.jit import bind, kernel
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import (
    FRAME_C,
    FRAME_E,
    FRAME_H,
    RobotKind,
    ScopeGeometry,
    build_urdf,
)
from lapwrench.robot.limits import JointLimits, arm_limits
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


@kernel
def fill_terms(out: KinematicTerms, q: Vec, dq: Vec, M_upper: Mat, R_E: Mat, R_H: Mat, R_C: Mat, J: Mat) -> None:
    """Copy the joint state and Pinocchio's matrices (column-major, in its own memory) into ``out``'s
    C-contiguous arrays: one compiled call instead of several NumPy conversions per tick."""
    out.q[:] = q
    out.dq[:] = dq
    out.M_upper[:] = M_upper
    out.R_E[:] = R_E
    out.R_H[:] = R_H
    out.R_C[:] = R_C
    out.J[:] = J


class ScopeAxis(NamedTuple):
    """The scope axis at one configuration, in {B}: the fields of :class:`Kinematics` that
    :mod:`lapwrench.rcm.geometry`'s ``rcm_error`` and ``insertion_depth`` read (p_E in m)."""

    p_E: Vec
    d_z: Vec
    P: Mat


@kernel
def fill_scope_axis(out: ScopeAxis, R_E: Mat, p_E: Vec) -> None:
    """``out`` = the scope axis (:func:`scope_axis`) of a placement held in Pinocchio's memory."""
    d_z, P = scope_axis(R_E)
    out.p_E[:] = p_E
    out.d_z[:] = d_z
    out.P[:] = P


_F64 = np.dtype(np.float64)


def _vector_arg(x: object, n: int, what: str) -> Vec:
    """``x`` as a C-contiguous float64 vector of length n (itself when it is one already)."""
    if type(x) is np.ndarray and x.dtype is _F64 and x.shape == (n,) and x.flags.c_contiguous:
        return x  # the common case, checked cheaply
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.shape != (n,):
        raise ValueError(f"{what} must be a vector of {n} values, got shape {a.shape}")
    return a


class RobotModel:
    """The arm of ``kind`` (fingers removed, ``nq = nv`` = its spec's joint count) with a laparoscope on
    the flange, in Pinocchio."""

    def __init__(self, kind: RobotKind = "panda", scope: ScopeGeometry | None = None) -> None:
        self.kind: RobotKind = kind
        self.spec = arm_spec(kind)  # ValueError (one line) for an arm that is not registered
        self.scope = scope or ScopeGeometry()
        self.urdf = build_urdf(kind, self.scope)
        self.model = pin.buildModelFromXML(self.urdf)
        self.data = self.model.createData()
        n = self.spec.n_joints
        if self.model.nq != n or self.model.nv != n:
            raise ValueError(f"expected a {n}-DoF arm, the {kind} description has nq={self.model.nq}")
        self.nq: int = self.model.nq
        self.nv: int = self.model.nv
        self.frame_E = self.model.getFrameId(FRAME_E)
        self.frame_H = self.model.getFrameId(FRAME_H)
        self.frame_C = self.model.getFrameId(FRAME_C)
        self.limits: JointLimits = arm_limits(kind, self.model)
        self._lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._axis_data = self.model.createData()  # scope_axis_at's own workspace
        self._bind_per_tick_calls()

    def _bind_per_tick_calls(self) -> None:
        """The arrays :meth:`terms` and :meth:`scope_axis_into` return, and their fill kernels bound to
        exactly these argument types (:func:`lapwrench.jit.bind`).

        Pinocchio's vectors are returned as they are: views of its memory (``data.nle``, a frame's
        ``translation``), which track every update. Its matrices are column-major, so they are copied
        into C-contiguous arrays by one compiled call per tick.
        """
        data, n = self.data, self.nv
        E, H, C = (data.oMf[f] for f in (self.frame_E, self.frame_H, self.frame_C))
        self._pin_matrices = (data.M, E.rotation, H.rotation, C.rotation)
        self._terms = KinematicTerms(
            np.zeros(n), np.zeros(n), np.zeros((n, n)), data.nle, data.g, E.translation, np.eye(3), H.translation,
            np.eye(3), C.translation, np.eye(3), np.zeros((6, n)),
        )
        t = self._terms
        J = pin.getFrameJacobian(self.model, data, self.frame_E, self._lwa)
        self._fill_terms = bind(fill_terms, t, t.q, t.dq, *self._pin_matrices, J)
        self._assemble = bind(assemble_kinematics, *t)
        axis_E = self._axis_data.oMf[self.frame_E]
        self._axis_placement = (axis_E.rotation, axis_E.translation)
        self._axis = ScopeAxis(np.zeros(3), np.zeros(3), np.zeros((3, 3)))
        self._fill_scope_axis = bind(fill_scope_axis, self._axis, *self._axis_placement)

    @property
    def length(self) -> float:
        return self.scope.length

    def terms(self, q: Vec, dq: Vec) -> KinematicTerms:
        """Pinocchio at (q, dq): one ``computeAllTerms``, the frame placements and the {E} Jacobian, as
        C-contiguous float64 arrays (the types the compiled tick is bound to).

        No allocation: the arrays are this model's own or views of Pinocchio's memory, all overwritten
        by the next evaluation on this model (:meth:`terms`, :meth:`kinematics`, :meth:`mass_matrix_inverse`,
        :meth:`frame_pose`). Use them before, or copy them (:meth:`kinematics` does)."""
        model, data = self.model, self.data
        q = _vector_arg(q, model.nq, "q")
        dq = _vector_arg(dq, self.nv, "dq")
        pin.computeAllTerms(model, data, q, dq)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, self.frame_E, self._lwa)
        self._fill_terms(self._terms, q, dq, *self._pin_matrices, J)
        return self._terms

    def kinematics(self, q: Vec, dq: Vec) -> Kinematics:
        """Evaluate the model at (q, dq) (:meth:`terms`, :func:`assemble_kinematics`); fresh arrays."""
        return self._assemble(*self.terms(q, dq))

    def mass_matrix_inverse(self, q: Vec) -> Mat:
        """M(q)⁻¹ by Pinocchio's ABA-based ``computeMinverse`` (symmetrised); a fresh array."""
        return symmetrised(pin.computeMinverse(self.model, self.data, q))

    def frame_pose(self, q: Vec, frame: str) -> pin.SE3:
        """Pose of a named frame at q (convenience, not for the control tick)."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.model.getFrameId(frame)].copy()

    def scope_axis_at(self, q: Vec) -> ScopeAxis:
        """The scope axis (eqs 16-17) at joints ``q``, e.g. the *measured* ones, in fresh arrays
        (:meth:`scope_axis_into`)."""
        return ScopeAxis(*(a.copy() for a in self.scope_axis_into(q)))

    def scope_axis_into(self, q: Vec) -> ScopeAxis:
        """The scope axis (eqs 16-17) at joints ``q``: one forward kinematics pass and the {E}
        placement (a few µs), on a workspace of its own so it never disturbs the tick's
        :meth:`terms`. Non-finite ``q`` gives non-finite values. The arrays are this model's own,
        overwritten by the next call here or in :meth:`scope_axis_at` (the 1 kHz path allocates nothing)."""
        model, data = self.model, self._axis_data
        pin.forwardKinematics(model, data, _vector_arg(q, model.nq, "q"))
        pin.updateFramePlacement(model, data, self.frame_E)
        self._fill_scope_axis(self._axis, *self._axis_placement)
        return self._axis
