"""lapwrench.robot.arms.ur5: the 6-DoF UR5 (simulation only), its published speed and torques and
the start pose found for it (the Panda's flange pose, far from every joint limit)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.robot.arms.spec import RobotDescriptionError
from lapwrench.robot.arms.ur5 import SPEC
from lapwrench.robot.model import RobotModel


@pytest.fixture(scope="module")
def model() -> RobotModel:
    try:
        return RobotModel("ur5")
    except RobotDescriptionError as exc:
        pytest.skip(str(exc))


def test_the_limits_are_the_published_ur5_ones() -> None:
    lim = SPEC.limits
    assert lim.velocity == (math.pi,) * 6  # 180 deg/s on every joint
    assert lim.torque == (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)


def test_it_is_a_six_joint_simulation_arm_that_takes_commands_as_references() -> None:
    assert SPEC.n_joints == 6 and not SPEC.hardware and not SPEC.differentiates_commands
    assert SPEC.flange_link == "tool0" and SPEC.home_pose == SPEC.sim_start_pose


def test_the_start_is_at_least_1_6_rad_from_every_limit(model: RobotModel) -> None:
    q = np.array(SPEC.sim_start_pose)
    margin = np.minimum(q - model.limits.position_lower, model.limits.position_upper - q)
    assert np.all(margin >= 1.6), margin


def test_the_torques_are_the_descriptions_efforts(model: RobotModel) -> None:
    np.testing.assert_array_equal(model.model.effortLimit, SPEC.limits.torque)
