"""The compiled maths of one control tick, top-down like the paper's Fig. 3.

:class:`~lapwrench.controller.Controller` validates the sensors and asks Pinocchio for the kinematics
and M once per tick (M⁻¹ by M's Cholesky factor); the rest is compiled, in two stages (one call when
no cue runs in Python, :func:`tick_stage`):

1. :func:`geometry_stage`: the adaptive RCM point (eq 19-26), the RCM error (eq 27), what the
   measured pose adds (:mod:`lapwrench.motion.measured_feedback`) and the task geometry (eq 28-36);
   :func:`tick_front` adds the kinematics, the hand's wrench from the F/T reading
   (:mod:`lapwrench.wrenches.ft_zero`), the measured scope axis and ΔF (eq 19) before it;
2. :func:`motion_stage`: the wrenches (eq 5-14, 40), the task/null-space allocation (eq 2-4, 37-39),
   the self-motion terms, the integration of the virtual model, the joint-limit box and the envelope rows.

Between them the controller evaluates the cues that run in Python (plugins,
:mod:`lapwrench.wrenches.base`) on the tick's geometry; the paper's four run here, each only when
the configuration's ``cues:`` section has it on.
When the desired acceleration breaks a limit, :func:`saturation_stage` meets the joint box and
the envelope by changing the lower-priority motion only (the QPs of :mod:`lapwrench.motion.saturation`,
compiled; the envelope gives way where it must); only when the RCM task cannot be kept does the
controller run the Python levels of :func:`lapwrench.motion.saturation.saturate`.
:func:`~lapwrench.motion.reference_shaper.advance_reference` gives the next reference. Each equation
is the one function of its module, compiled (:mod:`lapwrench.jit`); nothing here re-derives one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lapwrench.allocation import (
    nullspace_projector,
    nullspace_torque,
    nullspace_wrench,
    task_priority_torque,
    weighted_pseudo_inverse,
)
from lapwrench.jit import kernel, kernel_inlined
from lapwrench.motion.envelope import envelope_rows
from lapwrench.motion.measured_feedback import feedback_step
from lapwrench.motion.qp import QP_INFEASIBLE, QP_SOLVED
from lapwrench.motion.reference_shaper import acceleration_bounds, advance_reference
from lapwrench.motion.saturation import at_bound, solve_exact, solve_relaxed, violated
from lapwrench.motion.virtual_model import (
    add_self_motion_torque,
    damping_jacobian,
    euler_velocity_step,
    joint_limit_torque,
    self_motion_damping,
    self_motion_projector,
)
from lapwrench.rcm.adaptive import AdaptiveParams, AdaptiveState, adaptive_rcm_step, residual_force
from lapwrench.rcm.geometry import (
    TaskGeometry,
    closest_point,
    closest_point_jacobian,
    closest_point_parameter,
    lateral_rcm_jacobian,
    lateral_task,
    rcm_error,
    rcm_error_drift,
    rcm_error_rate,
    rcm_jacobian,
)
from lapwrench.robot.model import (
    Kinematics,
    KinematicTerms,
    ScopeAxis,
    assemble_kinematics,
    inverse_inertia,
    scope_axis,
)
from lapwrench.spatial import Mat, Vec, all_finite, matvec, matvec_into
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.ft_zero import FtTare, conditioned_ft
from lapwrench.wrenches.interaction import grip_gain, interaction_wrench
from lapwrench.wrenches.rcm import rcm_feedforward, rcm_force
from lapwrench.wrenches.tracking import virtual_force


@kernel_inlined
def geometry_stage(
    kin: Kinematics,
    rcm: AdaptiveState,
    adaptive: AdaptiveParams,
    residual: Vec,
    has_residual: bool,
    offsets: Vec,
    measured: ScopeAxis,
    has_measured: bool,
    p: TickParams,
) -> tuple[TaskGeometry, Vec]:
    """Steps 2-3 of the tick: the adaptive point (eq 19-26; ``rcm`` in place), the RCM error
    (eq 27), the measured-feedback offsets (``offsets`` in place) and the task geometry (eq 28-36).

    Returns the geometry and the mapped lateral residual F_re⊥ (eq 23).
    """
    twist = matvec(kin.J_E, kin.dq)
    F_lat = adaptive_rcm_step(rcm, kin.P, residual, has_residual, twist, p.dt, adaptive)
    snap = np.empty((3, 3))  # p_R, its velocity and e_R's offset as they are now: rows of one array
    p_R, velocity, e_R_offset = snap[0], snap[1], snap[2]
    p_R[:] = rcm.p_R
    axis = ScopeAxis(kin.p_E, kin.d_z, kin.P)  # for what reads only these: 2 atomic refcounts per array handed on
    e_R = rcm_error(axis, p_R)
    feedback_step(offsets, measured, has_measured, axis, p_R, e_R, p.length, p.feedback_gain, p.feedback_cap)
    J_R = lateral_rcm_jacobian(kin, p_R) if p.lateral else rcm_jacobian(kin, p_R)
    s_star = closest_point_parameter(axis, p_R, p.length)
    p_G, o_G = closest_point(axis, s_star, p.length)
    velocity[:], e_R_offset[:] = rcm.velocity, offsets[:3]
    geo = TaskGeometry(
        p_R, velocity, e_R, rcm_error_rate(kin, J_R, velocity), J_R, s_star, p_G, o_G,
        closest_point_jacobian(kin, o_G), e_R_offset,
    )
    return geo, F_lat


class MotionOutput(NamedTuple):
    """What :func:`motion_stage` computes: wrenches (``[moment; force]`` in {B}), torques, the desired
    acceleration and the limits it must meet."""

    W_r: Vec  # about p_R
    W_h: Vec  # about p_H
    W_c: Vec  # about p_C
    W_f: Vec  # about p_G
    W_n: Vec  # eq (38), about p_G
    delta: float
    contacts: int
    tau: Vec
    non_finite: bool  # the fused torque was not finite and was replaced by zero (braking)
    a_d: Vec  # desired joint acceleration of the virtual model (after the null-space brake, if stopping)
    a_lo: Vec  # joint box of the shaper
    a_hi: Vec
    J_task: Mat  # 2 x n lateral RCM task, [x_E y_E]ᵀ J_R
    env_W: Mat  # envelope rows on the twist of {E} (4 x 6), their bounds, scales and wall names
    env_lo: Vec
    env_hi: Vec
    env_scale: Vec
    env_wall: np.ndarray
    admitted: bool  # a_d meets the joint box and the envelope: nothing to saturate


@kernel_inlined
def null_brake(J_task: Mat, Minv: Mat, dq: Vec, stop_time: float) -> Vec:
    """N θ̇ / T_stop with N = I - J⁺ J (J⁺ M-weighted, eq 3-4): a deceleration of the null-space motion only."""
    J_pinv = weighted_pseudo_inverse(J_task, Minv)
    return (dq - J_pinv @ (J_task @ dq)) / stop_time


@kernel_inlined
def motion_stage(
    kin: Kinematics,
    Minv: Mat,
    geo: TaskGeometry,
    ft_force: Vec,
    ft_torque: Vec,
    has_ft: bool,
    tactile: Vec,
    has_tactile: bool,
    points: Mat,
    extra_W: Mat,
    extra_points: Mat,
    extra_D: Mat,
    extra_task_F: Vec,
    ddq_ref: Vec,
    stopping: bool,
    R_E0: Mat,
    depth_offset: float,
    p: TickParams,
) -> MotionOutput:
    """Steps 4-7 of the tick (module docstring). ``extra_*`` come from the cues that run in Python:
    the null-space cues' wrenches (rows about ``extra_points``) and the sum of their damping
    matrices (eq 40's form, 6 x 6), and the task-space cues' summed force at p_R."""
    # 4. wrenches (eq 5-14, 40), each in {B} about its own point; the paper's cues the config switched on
    J_pinv = weighted_pseudo_inverse(geo.J_R, Minv, kin.d_z) if p.lateral else weighted_pseudo_inverse(geo.J_R, Minv)
    n_extra = extra_W.shape[0]
    W = np.zeros((4 + n_extra, 6))  # W_r, W_h, W_c, W_f, then the Python cues' wrenches: one allocation
    W_r, W_h, W_c, W_f = W[0], W[1], W[2], W[3]
    W_r[3:] = rcm_force(geo.e_R + geo.e_R_offset, geo.e_R_rate, p.Kp, p.Kd)
    if p.rcm_feedforward:  # across the shaft only, whichever form of the task (wrenches/rcm.py)
        J_lat = geo.J_R if p.lateral else lateral_rcm_jacobian(kin, geo.p_R)
        J_lat_pinv = J_pinv if p.lateral else weighted_pseudo_inverse(J_lat, Minv, kin.d_z)
        W_r[3:] += rcm_feedforward(kin, Minv, J_lat, J_lat_pinv, rcm_error_drift(kin, geo.p_R, geo.rcm_velocity))
    delta, contacts = 0.0, 0
    if has_tactile:
        delta, contacts = grip_gain(tactile, p.k_H, p.k_min, p.contact_threshold)
    if p.cue_interaction and has_ft and delta != 0.0:
        W_h[:3], W_h[3:] = interaction_wrench(ft_force, ft_torque, kin.R_H, delta)
    if p.cue_tracking:
        W_c[3:] = virtual_force(points, p.tracking, kin.R_C)
    D = (p.D_guided if delta > 0.0 else p.D_unguided) if p.cue_viscous else np.zeros((6, 6))
    matvec_into(D, matvec(geo.J_G, kin.dq), W_f)
    for i in range(6):
        W_f[i] = -W_f[i]  # -D J_G θ̇

    # 5. task/null-space allocation (eq 2-4, 37-39) and the self-motion
    W_all = W[1:]  # the null-space wrenches (eq 38): W_h, W_c, W_f and the cues' rows
    P_all = np.zeros((3 + n_extra, 3))
    P_all[0], P_all[1], P_all[2] = kin.p_H, kin.p_C, geo.p_G
    W_all[3:] = extra_W
    P_all[3:] = extra_points
    N_r = nullspace_projector(geo.J_R, J_pinv)
    W_n = nullspace_wrench(W_all, P_all, geo.p_G)
    tau_n = np.zeros(kin.q.shape[0]) if stopping else nullspace_torque(geo.J_G, W_n)
    N_E_T = self_motion_projector(kin, Minv)
    B_self = self_motion_damping(kin, N_E_T, p.self_motion_damping)
    push = (joint_limit_torque(kin.q, p.q_lo, p.q_hi, p.joint_limit_zone, p.joint_limit_stiffness)
            if p.joint_limit_stiffness != 0.0 else np.zeros(kin.q.shape[0]))
    tau = task_priority_torque(geo.J_R, W_r[3:] + extra_task_F, N_r, tau_n)
    add_self_motion_torque(tau, N_E_T, push, B_self, kin.dq)

    # 6. integration of the virtual model, damping terms implicit
    B = damping_jacobian(geo.J_R, p.Kd, N_r, geo.J_G, D + extra_D, B_self)
    non_finite = not all_finite(tau)
    if non_finite:
        tau = np.zeros(kin.q.shape[0])
    a_d = euler_velocity_step(kin, tau, B, p.dt, p.integrator)  # θ̇⁺, made the acceleration in place
    for i in range(a_d.shape[0]):
        a_d[i] = (a_d[i] - kin.dq[i]) / p.dt

    # 7. the limits: joint box, envelope rows; the null-space brake while stopping
    a_lo, a_hi = acceleration_bounds(kin.q, kin.dq, ddq_ref, p.q_lo, p.q_hi, p.v_max, p.a_max, p.j_max, p.dt)
    J_task = lateral_task(kin.R_E, geo.J_R)
    if stopping:
        a_d = a_d - null_brake(J_task, Minv, kin.dq, p.stop_time)
    admitted = not violated(a_lo, a_hi, a_d, p.a_max)
    if p.envelope_enabled:
        env_W, env_lo, env_hi, env_scale, env_wall = envelope_rows(
            kin, geo.p_R, a_d, depth_offset, R_E0, p.envelope, p.length, p.dt
        )
        admitted = admitted and not violated(env_lo, env_hi, matvec(env_W, matvec(kin.J_E, a_d)), env_scale)
    else:
        env_W, env_lo, env_hi = np.zeros((4, 6)), np.zeros(4), np.zeros(4)
        env_scale, env_wall = np.ones(4), np.zeros(4, dtype=np.int64)
    return MotionOutput(
        W_r, W_h, W_c, W_f, W_n, delta, contacts, tau, non_finite, a_d, a_lo, a_hi, J_task,
        env_W, env_lo, env_hi, env_scale, env_wall, admitted,
    )


class SaturationInputs(NamedTuple):
    """Preallocated arrays the compiled tick fills for the saturation step on the ticks it does not admit
    (others keep the last such tick's values): the rows lo <= C a <= hi on the joint acceleration, the
    joint box first (n rows), then the envelope's four rows through J_E."""

    a_d: Vec
    J_task: Mat
    M: Mat
    C: Mat
    lo: Vec
    hi: Vec
    scale: Vec
    wall: np.ndarray  # the envelope rows' wall names (indices into WALL_NAMES)

    @staticmethod
    def allocate(n: int) -> SaturationInputs:
        return SaturationInputs(
            np.zeros(n), np.zeros((2, n)), np.eye(n), np.zeros((n + 4, n)), np.zeros(n + 4), np.zeros(n + 4),
            np.ones(n + 4), np.zeros(4, dtype=np.int64),
        )


@kernel_inlined
def fill_saturation_inputs(sat: SaturationInputs, o: MotionOutput, kin: Kinematics, a_max: Vec) -> None:
    """Write the saturation step's inputs into ``sat`` (the rows of :class:`SaturationInputs`)."""
    n = kin.q.shape[0]
    sat.a_d[:], sat.J_task[:], sat.M[:] = o.a_d, o.J_task, kin.M
    sat.C[:] = 0.0
    for i in range(n):
        sat.C[i, i] = 1.0
    sat.C[n:] = o.env_W @ kin.J_E
    sat.lo[:n], sat.hi[:n], sat.scale[:n] = o.a_lo, o.a_hi, a_max
    sat.lo[n:], sat.hi[n:], sat.scale[n:] = o.env_lo, o.env_hi, o.env_scale
    sat.wall[:] = o.env_wall


@kernel_inlined
def saturation_stage(sat: SaturationInputs, Minv: Mat, q: Vec, dq: Vec,
                     p: TickParams) -> tuple[bool, Mat, np.ndarray, bool]:
    """Step 7 when the desired acceleration breaks a limit: the box and envelope met with the RCM task kept
    (:func:`~lapwrench.motion.saturation.solve_exact`), else the envelope relaxed as little as the box allows
    (:func:`~lapwrench.motion.saturation.solve_relaxed`); then the next reference. Returns (solved, ref rows
    [q⁺, q̇⁺, q̈⁺], rows at or beyond a bound, clamped); not solved (task not kept, or non-finite a_d): Python."""
    n = q.shape[0]
    m = n + 4 if p.envelope_enabled else n
    ref = np.zeros((3, n))
    at = np.zeros(sat.lo.shape[0], dtype=np.bool_)
    if not all_finite(sat.a_d):
        return False, ref, at, False
    C, lo, hi, scale = sat.C[:m], sat.lo[:m], sat.hi[:m], sat.scale[:m]
    a, status = solve_exact(Minv, sat.a_d, sat.J_task, C, lo, hi, scale)
    if status == QP_INFEASIBLE and m > n:  # the envelope gives way to the robot's limits
        a, _, status = solve_relaxed(Minv, sat.M, sat.a_d, sat.J_task, C, lo, hi, scale, np.arange(m) < n)
    if status != QP_SOLVED:
        return False, ref, at, False
    ref[0], ref[1], ref[2], clamped = advance_reference(q, dq, a, sat.lo[:n], sat.hi[:n], p.dt)
    at[:m] = at_bound(C, lo, hi, scale, a)
    return True, ref, at, clamped


MotionTail = tuple[Mat, Mat, int, float, int, bool, bool, bool, bool]  # what motion_tail returns (its docstring)


@kernel_inlined
def motion_tail(
    kin: Kinematics, geo: TaskGeometry, ft_force: Vec, ft_torque: Vec, has_ft: bool, tactile: Vec, has_tactile: bool,
    points: Mat, extra_W: Mat, extra_points: Mat, extra_D: Mat, extra_task_F: Vec, ddq_ref: Vec, stopping: bool,
    R_E0: Mat, depth_offset: float, may_admit: bool, sat: SaturationInputs, p: TickParams,
) -> MotionTail:
    """M⁻¹ from the tick's M (:func:`~lapwrench.robot.model.inverse_inertia`), :func:`motion_stage`,
    then (with ``may_admit``) the next reference: directly when the desired acceleration meets every
    limit, through :func:`saturation_stage` when it does not. When it is not admitted, ``sat`` holds
    the saturation inputs (what the Python saturation levels need when neither gives the reference).

    Returns packed arrays (numba returns a few arrays much faster than many, or a named tuple; each
    array it hands to Python costs about 0.5 µs): ``W`` rows [W_r, W_h, W_c, W_f, W_n], ``ref`` rows
    [q⁺, q̇⁺, q̈⁺, τ] (the first three valid when admitted or saturated), and the scalars (which limit
    rows are at a bound as a bit mask, bit i for row i; δ, n_c, non-finite, admitted, saturated,
    clamped).
    """
    Minv = inverse_inertia(kin.M)
    o = motion_stage(
        kin, Minv, geo, ft_force, ft_torque, has_ft, tactile, has_tactile, points, extra_W, extra_points, extra_D,
        extra_task_F, ddq_ref, stopping, R_E0, depth_offset, p,
    )
    W = np.empty((5, 6))
    W[0], W[1], W[2], W[3], W[4] = o.W_r, o.W_h, o.W_c, o.W_f, o.W_n
    ref = np.zeros((4, kin.q.shape[0]))
    ref[3] = o.tau
    at_mask = 0
    admitted = o.admitted and may_admit
    if not admitted:
        fill_saturation_inputs(sat, o, kin, p.a_max)
    saturated, clamped = False, False
    if admitted:
        ref[0], ref[1], ref[2], clamped = advance_reference(kin.q, kin.dq, o.a_d, o.a_lo, o.a_hi, p.dt)
    elif may_admit:
        saturated, ref3, at, clamped = saturation_stage(sat, Minv, kin.q, kin.dq, p)
        ref[:3] = ref3
        for i in range(at.shape[0]):
            if at[i]:
                at_mask |= 1 << i
    return W, ref, at_mask, o.delta, o.contacts, o.non_finite, admitted, saturated, clamped


@kernel_inlined
def tick_front(
    terms: KinematicTerms, rcm: AdaptiveState, adaptive: AdaptiveParams, ext_force: Vec, has_ext: bool, offsets: Vec,
    R_measured: Mat, p_measured: Vec, has_measured: bool, ft_force: Vec, ft_torque: Vec, has_ft: bool, tactile: Vec,
    has_tactile: bool, tare: FtTare, p: TickParams,
) -> tuple[Kinematics, TaskGeometry, Vec, Vec, bool, Vec, Vec]:
    """The tick up to the cues: the kinematics from Pinocchio's terms; the hand's wrench from the F/T reading
    (:func:`~lapwrench.wrenches.ft_zero.conditioned_ft`: the grip's weight at {H}'s measured rotation, {H}
    being parallel to {E}, or the reference's without a measurement; the zero, ``tare.zero`` stepped in
    place); the scope axis at the measured joints from {E}'s measured placement (``R_measured``,
    ``p_measured``); ΔF (eq 19; zero unless the F/T and the robot's estimate are both valid) and
    :func:`geometry_stage`. Returns (kin, geo, F_re⊥, ΔF, has ΔF, the hand's force, its torque)."""
    kin = assemble_kinematics(terms.q, terms.dq, terms.M_upper, terms.nle, terms.gravity, terms.p_E, terms.R_E,
                              terms.p_H, terms.R_H, terms.p_C, terms.R_C, terms.J, terms.a)
    force, torque = ft_force, ft_torque
    if has_ft:
        R_H = R_measured if has_measured else terms.R_H  # both Pinocchio's (column-major) rotations
        force, torque = conditioned_ft(ft_force, ft_torque, R_H, tare.R_H0, p.grip_mass, p.grip_com, tare.zero,
                                       p.zero_gain, tactile, has_tactile, p.contact_threshold)
    has_residual = has_ft and has_ext
    residual = residual_force(matvec(kin.R_H, force), ext_force) if has_residual else np.zeros(3)
    d_z, P = scope_axis(R_measured)
    measured = ScopeAxis(p_measured, d_z, P)
    geo, F_lat = geometry_stage(kin, rcm, adaptive, residual, has_residual, offsets, measured, has_measured, p)
    return kin, geo, F_lat, residual, has_residual, force, torque


@kernel
def tick_stage(
    terms: KinematicTerms, rcm: AdaptiveState, adaptive: AdaptiveParams, ext_force: Vec, has_ext: bool, offsets: Vec,
    R_measured: Mat, p_measured: Vec, has_measured: bool, ft_force: Vec, ft_torque: Vec, has_ft: bool, tactile: Vec,
    has_tactile: bool, points: Mat, ddq_ref: Vec, stopping: bool, R_E0: Mat, may_admit: bool, sat: SaturationInputs,
    tare: FtTare, p: TickParams,
) -> tuple[Mat, bool, *MotionTail]:
    """The whole compiled tick in one call, when every cue is compiled (no Python cues): :func:`tick_front`
    and :func:`motion_tail` (on the hand's wrench, the conditioned F/T reading).

    Returns ``vec3`` rows [e_R, p_R, p_G, F_re⊥, ΔF], has ΔF, then what :func:`motion_tail` returns.
    """
    kin, geo, F_lat, residual, has_residual, force, torque = tick_front(terms, rcm, adaptive, ext_force, has_ext,
        offsets, R_measured, p_measured, has_measured, ft_force, ft_torque, has_ft, tactile, has_tactile, tare, p)
    W, ref, at_mask, delta, contacts, non_finite, admitted, saturated, clamped = motion_tail(
        kin, geo, force, torque, has_ft, tactile, has_tactile, points, np.zeros((0, 6)),
        np.zeros((0, 3)), np.zeros((6, 6)), np.zeros(3), ddq_ref, stopping, R_E0, offsets[3], may_admit, sat, p,
    )
    vec3 = np.empty((5, 3))
    vec3[0], vec3[1], vec3[2], vec3[3], vec3[4] = geo.e_R, geo.p_R, geo.p_G, F_lat, residual
    return vec3, has_residual, W, ref, at_mask, delta, contacts, non_finite, admitted, saturated, clamped
