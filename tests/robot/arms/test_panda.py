"""lapwrench.robot.arms.panda: the paper's arm, with the limits libfranka enforces (Franka Control
Interface, "Robot and interface specifications") and the start poses the FR3 shares."""

from __future__ import annotations

import numpy as np

from lapwrench.robot.arms.panda import FRANKA_HOME, FRANKA_SIM_START, SPEC
from lapwrench.robot.model import RobotModel


def test_the_limits_are_the_published_franka_ones() -> None:
    lim = SPEC.limits
    assert lim.velocity == (2.175,) * 4 + (2.61,) * 3
    assert lim.acceleration == (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
    assert lim.jerk == (7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0)
    assert lim.torque == (87.0,) * 4 + (12.0,) * 3 and lim.torque_rate == (1000.0,) * 7


def test_it_runs_on_the_hardware_path_which_differentiates_each_command() -> None:
    assert SPEC.hardware and SPEC.differentiates_commands and SPEC.command_period_s == 0.001
    assert SPEC.n_joints == 7 and SPEC.flange_link == "panda_link8" and SPEC.base_link == "panda_link0"
    assert SPEC.description.path().name == "panda.urdf"


def test_the_simulated_start_is_at_least_0_9_rad_from_every_limit() -> None:
    model = RobotModel("panda")
    q = np.array(FRANKA_SIM_START)
    margin = np.minimum(q - model.limits.position_lower, model.limits.position_upper - q)
    assert np.all(margin >= 0.9), margin
    assert SPEC.sim_start_pose == FRANKA_SIM_START and SPEC.home_pose == FRANKA_HOME != FRANKA_SIM_START


def test_the_servo_and_torque_bias_are_one_value_per_joint_and_positive_where_they_must_be() -> None:
    assert all(k > 0 for k in SPEC.servo_stiffness) and all(d > 0 for d in SPEC.servo_damping)
    assert max(abs(b) for b in SPEC.sim_torque_bias) < 0.2  # N m: a sensing imperfection, not a load
