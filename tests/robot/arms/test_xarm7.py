"""lapwrench.robot.arms.xarm7: the 7-DoF xArm7 (simulation only), its datasheet speed, the URDF's
torques, and the start pose found for it (the Panda's flange pose, far from every joint limit)."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.robot.arms.spec import RobotDescriptionError
from lapwrench.robot.arms.xarm7 import SPEC
from lapwrench.robot.model import RobotModel


@pytest.fixture(scope="module")
def model() -> RobotModel:
    try:
        return RobotModel("xarm7")
    except RobotDescriptionError as exc:
        pytest.skip(str(exc))


def test_the_limits_are_the_published_xarm7_ones() -> None:
    lim = SPEC.limits
    assert lim.velocity == (3.14,) * 7 and lim.acceleration == (10.0,) * 7  # half the SDK's 20 rad/s^2
    assert lim.torque == (50.0, 50.0, 30.0, 30.0, 30.0, 20.0, 20.0)


def test_it_is_a_simulation_arm_that_takes_commands_as_references() -> None:
    assert SPEC.n_joints == 7 and not SPEC.hardware and not SPEC.differentiates_commands
    assert SPEC.flange_link == "link7" and SPEC.home_pose == SPEC.sim_start_pose


def test_the_start_is_at_least_1_6_rad_from_every_limit(model: RobotModel) -> None:
    q = np.array(SPEC.sim_start_pose)
    margin = np.minimum(q - model.limits.position_lower, model.limits.position_upper - q)
    assert np.all(margin >= 1.6), margin


def test_the_torques_and_speeds_agree_with_the_description(model: RobotModel) -> None:
    np.testing.assert_array_equal(model.model.effortLimit, SPEC.limits.torque)
    np.testing.assert_allclose(model.model.velocityLimit, SPEC.limits.velocity)
