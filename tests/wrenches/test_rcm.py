"""lapwrench.wrenches.rcm: eq (13)-(14), the RCM wrench of the task space."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from helpers import kinematics_at_rest, random_configuration

from lapwrench.allocation import weighted_pseudo_inverse
from lapwrench.config import from_dict, load
from lapwrench.rcm.geometry import TaskGeometry, lateral_rcm_jacobian, rcm_error, rcm_error_drift
from lapwrench.robot.model import RobotModel, inverse_inertia
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.rcm import RcmCue, rcm_feedforward, rcm_force


def test_eq_14_is_a_spring_and_a_damper_on_the_rcm_error() -> None:
    e, de = np.array([1e-3, -2e-3, 0.0]), np.array([0.01, 0.0, 0.0])
    np.testing.assert_allclose(rcm_force(e, de, 300.0, 20.0), -300.0 * e - 20.0 * de)
    np.testing.assert_allclose(rcm_force(np.zeros(3), np.zeros(3), 300.0, 20.0), 0.0)


def test_the_cue_is_a_pure_force_at_p_R_including_the_measured_offset() -> None:
    cfg = from_dict({"rcm": {"feedforward": False}})  # eq (13)-(14) alone (the feed-forward: tests below)
    cue = RcmCue("rcm", cfg.rcm, cfg)
    z = np.zeros(3)
    geo = TaskGeometry(np.array([0.4, 0.0, 0.2]), z, np.array([1e-3, 0.0, 0.0]), z, np.zeros((3, 7)), 0.5,
                       z, z, np.zeros((6, 7)), np.array([0.0, 2e-3, 0.0]))

    class Ctx:
        geometry = geo

    w = cue.compute(Ctx())  # type: ignore[arg-type]
    assert cue.priority == "task" and cue.fused
    np.testing.assert_allclose(w.moment, 0.0)
    np.testing.assert_allclose(w.force, -cfg.rcm.Kp * np.array([1e-3, 2e-3, 0.0]))
    np.testing.assert_allclose(w.point, geo.p_R)


def _lateral_error_acceleration(model: RobotModel, q: np.ndarray, dq: np.ndarray, p_R: np.ndarray,
                                F: np.ndarray) -> np.ndarray:
    """P ë_R when the model (eq 1, gravity compensated) is driven by J_Rᵀ F alone: θ̈ from Pinocchio's ABA,
    ë_R by central differences of e_R along q(t) = q + t θ̇ + t² θ̈ / 2."""
    kin = model.kinematics(q, dq)
    J_R = lateral_rcm_jacobian(kin, p_R)
    ddq = pin.aba(model.model, model.model.createData(), q, dq, J_R.T @ F + kin.gravity)
    h = 1e-4
    e = [rcm_error(kinematics_at_rest(model, q + s * h * dq + 0.5 * (s * h) ** 2 * ddq), p_R) for s in (1.0, 0.0, -1.0)]
    return kin.P @ (e[0] - 2.0 * e[1] + e[2]) / h**2


@pytest.mark.parametrize("seed", range(4))
def test_the_feedforward_cancels_the_velocity_products_of_the_lateral_rcm_error(any_model: RobotModel,
                                                                                 seed: int) -> None:
    """With F = F_ff alone (no spring, no damper, no null-space torque) the RCM error does not accelerate
    across the shaft, at joint speeds of 1 rad/s; without it, it does (the terms eq 2 leaves in)."""
    rng = np.random.default_rng(seed)
    q, dq = random_configuration(any_model, rng), rng.uniform(-1.0, 1.0, any_model.nv)
    kin = any_model.kinematics(q, dq)
    p_R = kin.p_E + 0.23 * kin.d_z + 0.003 * rng.standard_normal(3)  # off the axis: e_R is not zero
    Minv = inverse_inertia(kin.M)
    J_R = lateral_rcm_jacobian(kin, p_R)
    J_pinv = weighted_pseudo_inverse(J_R, Minv, kin.d_z)
    F = rcm_feedforward(kin, Minv, J_R, J_pinv, rcm_error_drift(kin, p_R, np.zeros(3)))
    without = _lateral_error_acceleration(any_model, q, dq, p_R, np.zeros(3))
    assert np.abs(without).max() > 0.05  # m/s²: what the feed-forward has to cancel
    np.testing.assert_allclose(_lateral_error_acceleration(any_model, q, dq, p_R, F), 0.0,
                               atol=1e-4 * np.abs(without).max())
    assert abs(F @ kin.d_z) < 1e-9 * (1.0 + np.abs(F).max())  # nothing along the shaft: the lateral task


def test_the_feedforward_is_on_by_default_and_false_is_the_paper_s_eq_2() -> None:
    assert load().rcm.feedforward is True
    cfg = from_dict({"rcm": {"feedforward": False}})
    assert cfg.rcm.feedforward is False and TickParams.from_config(cfg, RobotModel().limits).rcm_feedforward is False


def test_near_the_ur5_wrist_singularity_the_feedforward_keeps_the_rcm_a_hard_push_broke() -> None:
    """The audit's case (2026-12-03): the UR5 with q5 = 0.05 rad, 17 N and 1.5 N m on the handle. Eq (2) as
    printed let the RCM error reach the supervisor's 5 mm and hold the arm; with the feed-forward it stays
    under 0.1 mm for the whole push."""
    import dataclasses

    from lapwrench.virtual import HandScript, run_virtual

    q0 = np.array([0.5963, -2.5831, 1.5997, -1.6697, 0.05, -1.0917])
    force, torque = np.array([-1.2012, -4.4810, 17.2102]), np.array([-0.6456, -0.5150, -1.2230])
    hand = HandScript(lambda t: force, lambda t: torque, lambda t: 2.0)
    base = load()
    runs = {}
    for ff in (False, True):
        cfg = dataclasses.replace(base, robot=dataclasses.replace(base.robot, kind="ur5"),
                                  rcm=dataclasses.replace(base.rcm, feedforward=ff))
        runs[ff] = run_virtual(cfg, 1.5, hand, q0=q0)[1]
    assert runs[False].alarm is not None and runs[False].alarm.startswith("rcm_error")
    assert runs[True].alarm is None and runs[True].array("rcm_error").max() < 1e-4


def test_with_the_printed_task_the_feedforward_stays_across_the_shaft_and_small() -> None:
    """``motion.rcm_task: printed`` inverts the 3-row J_R, whose Λ_R grows as 1/|e_R|² along the shaft, where
    ë_R is set by the geometry: cancelling there asked for 3092 N at p_R from 20 µm off the axis under a
    brisk hand (a review's closed loop). Only the part across the shaft is cancelled, as with the lateral task."""
    import dataclasses

    from lapwrench.virtual import HandScript, home_pose, run_virtual

    base = load()
    model = RobotModel("panda")
    q0 = home_pose("panda")
    kin = model.kinematics(q0, np.zeros(7))
    across = np.cross(kin.d_z, [0.0, 0.0, 1.0])
    p_R = kin.p_E + base.scope.lambda0 * model.length * kin.d_z + 2e-5 * across / np.linalg.norm(across)
    hand = HandScript(lambda t: np.array([25.0, 0.0, 5.0]) * np.sin(6 * t),
                      lambda t: np.array([0.0, 2.0, 0.0]) * np.cos(5 * t), lambda t: 2.0)
    cfg = dataclasses.replace(base, motion=dataclasses.replace(base.motion, rcm_task="printed"))
    assert cfg.rcm.feedforward
    log = run_virtual(cfg, 0.6, hand, q0=q0, p_R=p_R)[1]
    forces = np.array([r.wrenches["rcm"][3:] for r in log.results])
    axes = np.array([model.kinematics(r.q_ref, r.dq_ref).d_z for r in log.results])
    assert log.alarm is None and np.abs(forces).max() < 1.0  # N: a spring on 20 µm plus the feed-forward
    assert np.abs(np.einsum("ij,ij->i", forces, axes)).max() < 1e-3  # nothing along the shaft
