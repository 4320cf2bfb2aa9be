"""The virtual model's integration: semi-implicit damping, self-motion damping, the joint-limit push."""

from __future__ import annotations

import numpy as np

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.motion.virtual_model import joint_limit_torque, self_motion_damping, self_motion_projector
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0


def _damped_step_matrices(ctrl: Controller) -> tuple[np.ndarray, np.ndarray]:
    """Velocity-update matrices of the damping terms alone, explicit and semi-implicit."""
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    from lapwrench.allocation import nullspace_projector, weighted_pseudo_inverse
    from lapwrench.motion.virtual_model import damping_jacobian
    from lapwrench.rcm.geometry import closest_point, closest_point_jacobian, lateral_rcm_jacobian

    assert ctrl.rcm is not None
    J_R = lateral_rcm_jacobian(kin, ctrl.rcm.p_R)
    J_G = closest_point_jacobian(kin, closest_point(kin, 0.8, ctrl.cfg.scope.length)[1])
    Minv = np.linalg.inv(kin.M)
    N_r = nullspace_projector(J_R, weighted_pseudo_inverse(J_R, Minv, kin.d_z))
    B_s = self_motion_damping(kin, self_motion_projector(kin, Minv), 10.0)
    B = damping_jacobian(J_R, ctrl.cfg.rcm.Kd, N_r, J_G, ctrl.params.D_unguided, B_s)
    dt = ctrl.dt
    explicit = np.eye(7) - dt * Minv @ B
    implicit = np.linalg.solve(kin.M + dt * B, kin.M)
    return explicit, implicit


def test_explicit_euler_is_unstable_with_the_paper_damping_and_semi_implicit_is_not() -> None:
    ctrl = Controller(load().replace(viscous={"k_f": 2.0, "k_t_unguided": 150.0}))
    ctrl.reset(DEFAULT_Q0)
    explicit, implicit = _damped_step_matrices(ctrl)
    assert np.max(np.abs(np.linalg.eigvals(explicit))) > 1.0
    assert np.max(np.abs(np.linalg.eigvals(implicit))) <= 1.0 + 1e-9


def test_self_motion_damping_does_not_move_the_end_effector() -> None:
    model = RobotModel("panda")
    rng = np.random.default_rng(0)
    kin = model.kinematics(DEFAULT_Q0, rng.standard_normal(7))
    Minv = np.linalg.inv(kin.M)
    B = self_motion_damping(kin, self_motion_projector(kin, Minv), 10.0)
    acc_E = kin.J_E @ Minv @ B @ kin.dq
    assert np.linalg.norm(acc_E) < 1e-6 * np.linalg.norm(kin.J_E) * np.linalg.norm(Minv @ B @ kin.dq)
    assert kin.dq @ B @ kin.dq >= 0.0


def test_joint_limit_push_acts_only_inside_the_zone_and_only_on_the_self_motion() -> None:
    model = RobotModel("panda")
    lim = model.limits
    lo, hi = lim.position_lower, lim.position_upper
    mid = 0.5 * (lo + hi)
    assert not joint_limit_torque(mid, lo, hi, 0.3, 20.0).any()
    # Off the arm's vertical plane: with q1 = q3 = q5 = 0 the self-motion does not involve joints 4
    # and 6 at all, so nothing of this push is left after the projection (gᵀ M⁻¹ N_Eᵀ g = 0).
    q = DEFAULT_Q0 + np.array([0.3, 0.0, 0.4, 0.0, 0.2, 0.0, 0.0])
    q[3] = lo[3] + 0.1  # 0.2 rad into the lower zone of joint 4
    q[5] = hi[5] - 0.05  # 0.25 rad into the upper zone of joint 6
    g = joint_limit_torque(q, lo, hi, 0.3, 20.0)
    np.testing.assert_allclose(g, [0, 0, 0, 4.0, 0, -5.0, 0], atol=1e-9)
    kin = model.kinematics(q, np.zeros(7))
    Minv = np.linalg.inv(kin.M)
    tau = self_motion_projector(kin, Minv) @ g
    assert np.linalg.norm(kin.J_E @ Minv @ tau) < 1e-6 * np.linalg.norm(Minv @ g)
    assert g @ Minv @ tau > 1e-6 * (g @ Minv @ g)  # what is left still pushes away from the limits


def test_self_motion_moves_a_joint_out_of_its_limit_zone_without_moving_the_scope() -> None:
    from lapwrench.virtual import run_virtual

    cfg = load()
    lim = RobotModel("panda").limits
    q0 = DEFAULT_Q0.copy()
    q0[2] = lim.position_upper[2] - cfg.robot.position_margin - 0.1  # 0.2 rad into joint 3's zone
    ctrl, log = run_virtual(cfg, 2.0, q0=q0)
    q_end = log.results[-1].q_ref
    assert q_end[2] < q0[2] - 0.02  # pushed away from the limit
    kin0 = ctrl.model.kinematics(q0, np.zeros(7))
    kin1 = ctrl.model.kinematics(q_end, np.zeros(7))
    assert np.linalg.norm(kin1.p_E - kin0.p_E) < 1e-3 and np.linalg.norm(kin1.d_z - kin0.d_z) < 5e-3
    off = load().replace(motion={"joint_limit_stiffness": 0.0})
    _, log_off = run_virtual(off, 2.0, q0=q0)
    assert abs(log_off.results[-1].q_ref[2] - q0[2]) < 1e-6  # without the push the joint stays
