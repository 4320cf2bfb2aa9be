"""Franka Research 3 (7-DoF). Description: franky-sim's ``fr3_clean.urdf`` (links without geometry:
the scene draws capsules)."""

from __future__ import annotations

from lapwrench.robot.arms.panda import (
    FRANKA_HOME,
    FRANKA_SERVO_DAMPING,
    FRANKA_SERVO_STIFFNESS,
    FRANKA_SIM_START,
    FRANKA_TORQUE_BIAS,
)
from lapwrench.robot.arms.spec import ArmSpec, JointLimitTable, PackageUrdf, ScopeMount, SimLook

SPEC = ArmSpec(
    name="fr3",
    description=PackageUrdf("franky-sim", "franky_sim/assets/fr3_clean.urdf"),
    joint_names=tuple(f"joint{i}" for i in range(1, 8)),
    base_link="link0",
    mount=ScopeMount("link8"),
    # Franka Research 3 datasheet / libfranka's FR3 limits (Cartesian-independent joint limits)
    limits=JointLimitTable(
        velocity=(2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26),
        acceleration=(10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0),
        jerk=(5000.0, 5000.0, 5000.0, 5000.0, 5000.0, 5000.0, 5000.0),
        torque=(87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
        torque_rate=(1000.0, 1000.0, 1000.0, 1000.0, 1000.0, 1000.0, 1000.0),
    ),
    home_pose=FRANKA_HOME,
    sim_start_pose=FRANKA_SIM_START,
    servo_stiffness=FRANKA_SERVO_STIFFNESS,
    servo_damping=FRANKA_SERVO_DAMPING,
    sim_torque_bias=FRANKA_TORQUE_BIAS,
    differentiates_commands=True,  # libfranka differentiates each joint position command over 1 ms
    command_period_s=0.001,
    hardware=True,  # lapwrench.hardware.franka (pylibfranka), and franky-sim
    look=SimLook(rgba=(0.93, 0.93, 0.93, 1.0)),
)
