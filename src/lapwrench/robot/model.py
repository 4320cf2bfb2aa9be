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
    RobotDescriptionError,
    RobotKind,
    ScopeGeometry,
    build_urdf,
)
from lapwrench.robot.limits import JointLimits, arm_limits
from lapwrench.spatial import Mat, Vec, cholesky_inverse


class Kinematics(NamedTuple):
    """Robot state and derived quantities at one instant, all in the base frame {B}.

    A named tuple of arrays, so the compiled maths (:mod:`lapwrench.jit`) reads it as it is.

    ``J_E`` is the geometric Jacobian of the {E} origin ordered ``[J_Ew; J_Ev]`` (eq 33).
    ``d_z`` is the scope axis (eq 16) and ``P`` the projector orthogonal to it (eq 17), both
    filled by :func:`scope_axis`. ``a_E`` is {E}'s acceleration when θ̈ = 0, ``J̇_E θ̇`` ordered as
    ``J_E`` (its angular part and its origin's classical linear acceleration): the velocity-product
    part of the scope's motion (:func:`lapwrench.rcm.geometry.rcm_error_drift`).
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
    a_E: Vec

    @property
    def twist_E(self) -> Vec:
        """[angular; linear] velocity of {E} (eq 33)."""
        return self.J_E @ self.dq


@kernel
def scope_axis(R_E: Mat) -> tuple[Vec, Mat]:
    """Eqs (16)-(17): d_z = R_E I_z (the laparoscope direction) and P = I3 - d_z d_zᵀ."""
    d, P = np.empty(3), np.empty((3, 3))
    scope_axis_into(R_E, d, P)
    return d, P


@kernel
def scope_axis_into(R_E: Mat, d: Vec, P: Mat) -> None:
    """:func:`scope_axis` written into ``d`` and ``P``."""
    for i in range(3):
        d[i] = R_E[i, 2]
    for i in range(3):
        for j in range(3):
            P[i, j] = (1.0 if i == j else 0.0) - d[i] * d[j]


class KinematicTerms(NamedTuple):
    """What Pinocchio gives per tick, before :func:`assemble_kinematics` (frames' origins and rotations in
    {B}; ``M_upper`` has only its upper triangle filled; ``J`` is Pinocchio's ``[J_v; J_ω]`` of {E},
    LOCAL_WORLD_ALIGNED; ``a`` its classical acceleration ``[a_v; a_ω]`` at θ̈ = 0, in the same frame).

    The arrays are Pinocchio's own, as it gives them (:meth:`RobotModel.terms`): its matrices are
    column-major (``M_upper``, the rotations); :func:`assemble_kinematics` copies everything into the
    C-contiguous arrays of :class:`Kinematics`, so nothing converts them beforehand."""

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
    a: Vec


@kernel
def symmetrised(A_upper: Mat) -> Mat:
    """The symmetric matrix whose upper triangle is that of ``A_upper`` (Pinocchio fills only that one)."""
    A = np.empty(A_upper.shape)
    symmetrise_into(A, A_upper)
    return A


@kernel
def symmetrise_into(A: Mat, A_upper: Mat) -> None:
    """``A`` = :func:`symmetrised` ``(A_upper)``, written into ``A``."""
    n = A_upper.shape[0]
    for i in range(n):
        for j in range(n):
            A[i, j] = A_upper[i, j] if i <= j else A_upper[j, i]


@kernel
def assemble_kinematics(
    q: Vec, dq: Vec, M_upper: Mat, nle: Vec, gravity: Vec, p_E: Vec, R_E: Mat, p_H: Vec, R_H: Mat,
    p_C: Vec, R_C: Mat, J: Mat, a: Vec,
) -> Kinematics:
    """The tick's :class:`Kinematics` from Pinocchio's terms: M symmetrised, J_E = [J_ω; J_v] (eq 33),
    the scope axis (eqs 16-17); every array copied.

    The arrays are disjoint views of one buffer: one allocation instead of fourteen (each costs about
    as much as a small equation's arithmetic)."""
    n = q.shape[0]
    buf = np.empty(4 * n + n * n + 6 * n + 4 * 12 + 6)
    q_, dq_, nle_, g_ = buf[0:n], buf[n:2 * n], buf[2 * n:3 * n], buf[3 * n:4 * n]
    at = 4 * n
    M = buf[at:at + n * n].reshape((n, n))
    at += n * n
    J_E = buf[at:at + 6 * n].reshape((6, n))
    at += 6 * n  # then four (3-vector, 3 x 3) pairs: {E}, {H}, {C} and the scope axis (d_z, P)
    p_E_, R_E_ = buf[at:at + 3], buf[at + 3:at + 12].reshape((3, 3))
    p_H_, R_H_ = buf[at + 12:at + 15], buf[at + 15:at + 24].reshape((3, 3))
    p_C_, R_C_ = buf[at + 24:at + 27], buf[at + 27:at + 36].reshape((3, 3))
    axis = ScopeAxis(p_E_, buf[at + 36:at + 39], buf[at + 39:at + 48].reshape((3, 3)))
    a_E = buf[at + 48:at + 54]
    q_[:], dq_[:], nle_[:], g_[:] = q, dq, nle, gravity
    a_E[:3], a_E[3:] = a[3:], a[:3]
    symmetrise_into(M, M_upper)
    J_E[:3] = J[3:]
    J_E[3:] = J[:3]
    R_E_[:], p_H_[:], R_H_[:], p_C_[:], R_C_[:] = R_E, p_H, R_H, p_C, R_C
    fill_scope_axis(axis, R_E, p_E)
    return Kinematics(q_, dq_, M, nle_, g_, p_E_, R_E_, J_E, p_H_, R_H_, p_C_, R_C_, axis.d_z, axis.P, a_E)


@kernel
def inverse_inertia(M: Mat) -> Mat:
    """M⁻¹ of the joint-space inertia (symmetric positive definite) by its Cholesky factor
    (:func:`~lapwrench.spatial.cholesky_inverse`): once per tick inside the compiled maths, from the M
    Pinocchio gave. Not a number everywhere when M is not positive definite (e.g. at a non-finite q),
    so the tick's non-finite guard sees it."""
    Minv, ok = cholesky_inverse(M)
    if not ok:
        Minv[:] = np.nan
    return Minv


class ScopeAxis(NamedTuple):
    """The scope axis at one configuration, in {B}: the fields of :class:`Kinematics` that
    :mod:`lapwrench.rcm.geometry`'s ``rcm_error`` and ``insertion_depth`` read (p_E in m)."""

    p_E: Vec
    d_z: Vec
    P: Mat


@kernel
def fill_scope_axis(out: ScopeAxis, R_E: Mat, p_E: Vec) -> None:
    """``out`` = the scope axis (:func:`scope_axis`) of a placement held in Pinocchio's memory."""
    out.p_E[:] = p_E
    scope_axis_into(R_E, out.d_z, out.P)


_F64 = np.dtype(np.float64)  # compared with ==: the tick's reference (numba's cached kernels) has an equal one


def _vector_arg(x: object, n: int, what: str) -> Vec:
    """``x`` as a C-contiguous float64 vector of length n (itself when it is one already)."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.ndim == 1 and len(x) == n and x.flags.c_contiguous:
        return x  # the common case, checked cheaply (no shape tuple built)
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
        try:
            self.model = pin.buildModelFromXML(self.urdf)
        except (ValueError, RuntimeError) as exc:  # after check_description's checks: Pinocchio's own refusal
            raise RobotDescriptionError(f"{self.spec.urdf_path()}: Pinocchio cannot build the {kind} model "
                                        f"({' '.join(str(exc).split())[:200]})") from exc
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
        """The arrays :meth:`terms` and :meth:`scope_axis_into` hand out, and the kernels bound to exactly
        their types (:func:`lapwrench.jit.bind`).

        Pinocchio's arrays are handed out as they are: views of its memory (``data.M``, ``data.nle``, a
        frame's ``rotation`` and ``translation``), which track every update; its matrices are
        column-major, and the compiled tick is bound to that layout. Only the Jacobian and {E}'s
        acceleration are fresh arrays per call.
        """
        data, n = self.data, self.nv
        E, H, C = (data.oMf[f] for f in (self.frame_E, self.frame_H, self.frame_C))
        self._views = (data.M, data.nle, data.g, E.translation, E.rotation, H.translation, H.rotation,
                       C.translation, C.rotation)
        self._q, self._dq = np.zeros(n), np.zeros(n)
        self._assemble = bind(assemble_kinematics, *self.terms(np.zeros(n), np.zeros(n)))
        axis_E = self._axis_data.oMf[self.frame_E]
        self._axis_placement = (axis_E.rotation, axis_E.translation)
        self._axis = ScopeAxis(np.zeros(3), np.zeros(3), np.zeros((3, 3)))
        self._fill_scope_axis = bind(fill_scope_axis, self._axis, *self._axis_placement)

    @property
    def length(self) -> float:
        return self.scope.length

    def terms(self, q: Vec, dq: Vec) -> KinematicTerms:
        """Pinocchio at (q, dq): one ``computeAllTerms``, the frame placements, the {E} Jacobian and {E}'s
        acceleration at θ̈ = 0 (``computeAllTerms`` leaves the joints' at θ̈ = 0 in its data), as
        float64 arrays in the layouts the compiled tick is bound to (Pinocchio's own: its matrices are
        column-major).

        Hardly any allocation: q and dq are copied into this model's arrays, the rest are views of
        Pinocchio's memory, all overwritten by the next evaluation on this model (:meth:`terms`,
        :meth:`kinematics`, :meth:`mass_matrix_inverse`, :meth:`frame_pose`); only the Jacobian is
        fresh, as is {E}'s acceleration. Use them before, or copy them (:meth:`kinematics` does)."""
        model, data = self.model, self.data
        q = _vector_arg(q, model.nq, "q")
        dq = _vector_arg(dq, self.nv, "dq")
        pin.computeAllTerms(model, data, q, dq)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, self.frame_E, self._lwa)
        if not J.flags.c_contiguous:  # the layout the tick is bound to (Pinocchio gives it)
            J = np.ascontiguousarray(J)
        a = pin.getFrameClassicalAcceleration(model, data, self.frame_E, self._lwa).np
        self._q[:] = q
        self._dq[:] = dq
        M, nle, g, p_E, R_E, p_H, R_H, p_C, R_C = self._views
        # tuple.__new__: the named tuple without its keyword-handling constructor (this runs every tick)
        return tuple.__new__(KinematicTerms, (self._q, self._dq, M, nle, g, p_E, R_E, p_H, R_H, p_C, R_C, J, a))

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
        self._fill_scope_axis(self._axis, *self.placement_E_into(q))
        return self._axis

    def placement_E_into(self, q: Vec) -> tuple[Mat, Vec]:
        """{E}'s rotation (column-major) and origin in {B} at joints ``q``, on :meth:`scope_axis_into`'s
        workspace: views of Pinocchio's memory, overwritten by the next call here or there. The
        compiled tick takes the scope axis at the measured joints from these."""
        model, data = self.model, self._axis_data
        pin.forwardKinematics(model, data, _vector_arg(q, model.nq, "q"))
        pin.updateFramePlacement(model, data, self.frame_E)
        return self._axis_placement
