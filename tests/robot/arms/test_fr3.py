"""lapwrench.robot.arms.fr3: the Franka Research 3, Panda kinematics with its own (datasheet) limits,
on the hardware path and in franky-sim."""

from __future__ import annotations

import pytest

from lapwrench.robot.arms import fr3, panda
from lapwrench.robot.arms.spec import RobotDescriptionError

SPEC = fr3.SPEC


def test_the_limits_are_the_fr3_datasheet_ones() -> None:
    lim = SPEC.limits
    assert lim.velocity == (2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26)
    assert lim.acceleration == (10.0,) * 7 and lim.jerk == (5000.0,) * 7
    assert lim.torque == panda.SPEC.limits.torque  # same drives as the Panda


def test_it_shares_the_pandas_start_poses_servo_and_torque_sensing() -> None:
    for field in ("home_pose", "sim_start_pose", "servo_stiffness", "servo_damping", "sim_torque_bias"):
        assert getattr(SPEC, field) == getattr(panda.SPEC, field), field


def test_it_is_a_hardware_arm_with_frankas_command_semantics() -> None:
    assert SPEC.hardware and SPEC.differentiates_commands and SPEC.command_period_s == 0.001
    assert SPEC.joint_names == tuple(f"joint{i}" for i in range(1, 8)) and SPEC.flange_link == "link8"


def test_its_description_comes_from_franky_sim() -> None:
    assert SPEC.description.distribution == "franky-sim"
    try:
        path = SPEC.description.path()
    except RobotDescriptionError as exc:
        assert "pip install franky-sim" in str(exc)
        pytest.skip(str(exc))
    assert path.name == "fr3_clean.urdf"
