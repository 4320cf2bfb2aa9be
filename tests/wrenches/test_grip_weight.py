"""The grip's weight in the F/T reading (lapwrench.wrenches.grip_weight), and the controller taking it off."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.config import Config
from lapwrench.controller import Controller
from lapwrench.sensors import ForceTorqueReading, RobotReading, SensorFrame, TactileReading
from lapwrench.virtual import home_pose
from lapwrench.wrenches.grip_weight import GRAVITY_B, grip_weight_change, without_grip_weight


def _weight(R_H: np.ndarray, mass: float, com: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What an untared sensor reads from an untouched grip: m R_Hᵀ g and c x it (by numpy)."""
    F = mass * R_H.T @ GRAVITY_B
    return F, np.cross(com, F)


@pytest.mark.parametrize("seed", range(5))
def test_the_change_is_the_weight_now_minus_the_weight_at_the_tare(seed: int) -> None:
    rng = np.random.default_rng(seed)
    R0, R = (pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)) for _ in range(2))
    m, c = rng.uniform(0.01, 1.0), rng.uniform(-0.1, 0.1, 3)
    dF, dT = grip_weight_change(R, R0, m, c)
    np.testing.assert_allclose(dF, _weight(R, m, c)[0] - _weight(R0, m, c)[0], atol=1e-12)
    np.testing.assert_allclose(dT, _weight(R, m, c)[1] - _weight(R0, m, c)[1], atol=1e-12)
    assert np.all(grip_weight_change(R0, R0, m, c)[0] == 0.0)  # at the tare's pose nothing is added


def test_column_major_rotations_read_the_same() -> None:
    """Pinocchio hands rotations over column-major: the kernel must read them as the same matrices."""
    R0, R = pin.rpy.rpyToMatrix(0.2, 0.1, -0.3), pin.rpy.rpyToMatrix(-0.5, 0.4, 1.0)
    c = np.array([0.01, 0.02, 0.03])
    a = grip_weight_change(np.asfortranarray(R), np.asfortranarray(R0), 0.3, c)
    b = grip_weight_change(np.ascontiguousarray(R), np.ascontiguousarray(R0), 0.3, c)
    np.testing.assert_allclose(a[0], b[0], atol=1e-15)
    np.testing.assert_allclose(a[1], b[1], atol=1e-15)


def test_taking_the_weight_off_leaves_the_hand() -> None:
    R0, R = pin.rpy.rpyToMatrix(0.0, np.pi, 0.0), pin.rpy.rpyToMatrix(0.0, np.pi - 0.5, 0.3)
    m, c = 0.2, np.array([0.0, 0.0, 0.02])
    hand_F, hand_T = np.array([1.0, -2.0, 0.5]), np.array([0.0, 0.0, 0.1])
    dF, dT = grip_weight_change(R, R0, m, c)
    F, T = without_grip_weight(hand_F + dF, hand_T + dT, R, R0, m, c)
    np.testing.assert_allclose(F, hand_F, atol=1e-12)
    np.testing.assert_allclose(T, hand_T, atol=1e-12)
    assert np.linalg.norm(dF) > 0.9  # 0.2 kg turned by about 30°: about 1 N the hand never applied


def _frame(ctrl: Controller, q: np.ndarray, force: np.ndarray, torque: np.ndarray) -> SensorFrame:
    z = np.zeros(3)
    return SensorFrame(0.0, ForceTorqueReading(force, torque, 0.0), TactileReading(np.full(64, 200.0), 0.0),
                       None, RobotReading(q, np.zeros(ctrl.model.nv), z, 0.0))


@pytest.mark.parametrize("mass", [0.0, 0.3])
def test_the_controller_takes_the_weight_off_at_the_measured_joints(mass: float) -> None:
    """The reading of an untouched grip, tared at the start pose and read with the wrist turned, gives no
    interaction wrench: the weight's change is taken off at the *measured* joints (the reference has
    not moved). With mass 0 nothing is taken off."""
    cfg = Config().replace(scope={"grip_mass": mass, "grip_com": [0.0, 0.0, 0.02]})
    ctrl = Controller(cfg)
    q0 = home_pose(cfg.robot.kind)
    ctrl.reset(q0)
    q = q0.copy()
    q[5] += 0.4  # the wrist turned the handle by 0.4 rad
    R0 = ctrl.model.kinematics(q0, 0 * q0).R_H
    R = ctrl.model.kinematics(q, 0 * q).R_H
    dF, dT = grip_weight_change(R, R0, 0.3, np.array([0.0, 0.0, 0.02]))  # what a 0.3 kg grip adds
    r = ctrl.tick(_frame(ctrl, q, dF.copy(), dT.copy()))
    W_h = r.wrenches["interaction"]
    if mass:
        assert np.linalg.norm(W_h) < 1e-9
    else:
        assert np.linalg.norm(W_h[3:]) == pytest.approx(r.delta * np.linalg.norm(dF), rel=1e-9)
        assert np.linalg.norm(dF) > 0.5


def test_the_tare_pose_can_differ_from_the_start_pose_and_is_checked() -> None:
    """A restart at a turned pose keeps the F/T's tare from before (``Controller.reset(tare_q=...)``): the
    weight is taken off relative to the tare's pose, and a bad ``tare_q`` is a clear error."""
    cfg = Config()
    ctrl = Controller(cfg)
    q_tare = home_pose(cfg.robot.kind)
    q = q_tare.copy()
    q[5] += 0.4
    ctrl.reset(q, tare_q=q_tare)
    R0 = ctrl.model.kinematics(q_tare, 0 * q).R_H
    R = ctrl.model.kinematics(q, 0 * q).R_H
    m, c = cfg.scope.grip_mass, np.array(cfg.scope.grip_com)
    dF, dT = grip_weight_change(R, R0, m, c)
    r = ctrl.tick(_frame(ctrl, q, dF.copy(), dT.copy()))
    assert np.linalg.norm(r.wrenches["interaction"]) < 1e-9
    for bad in (q_tare[:3], np.full(7, np.nan), "home"):
        with pytest.raises(ValueError, match="tare_q"):
            ctrl.reset(q, tare_q=bad)  # type: ignore[arg-type]
