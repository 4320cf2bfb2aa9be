"""Franka Emika Panda (7-DoF): the paper's arm. Description: example-robot-data's ``panda.urdf``."""

from __future__ import annotations

import math

from lapwrench.robot.arms.spec import ArmSpec, JointLimitTable, PackageUrdf, ScopeMount, SimLook

# Start poses, simulated servo and torque sensing: shared with the FR3 (same kinematics).
FRANKA_HOME = (0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785)
# flange 0.482 m above the base, 0.5 m in front, scope straight down, >= 0.9 rad from every limit
FRANKA_SIM_START = (0.0, -0.1774, 0.0, -2.1379, 0.0, 1.9606, math.pi / 4)
# libfranka's default joint impedance; damping about critical with the arm's inertia + armature
FRANKA_SERVO_STIFFNESS = (3000.0, 3000.0, 3000.0, 2500.0, 2500.0, 2000.0, 2000.0)
FRANKA_SERVO_DAMPING = (150.0, 150.0, 110.0, 100.0, 40.0, 40.0, 30.0)
# a Franka-like torque sensing imperfection (N m)
FRANKA_TORQUE_BIAS = (0.08, -0.1, 0.05, 0.1, -0.02, 0.03, 0.01)

SPEC = ArmSpec(
    name="panda",
    description=PackageUrdf("example-robot-data", "panda_description/urdf/panda.urdf"),
    joint_names=tuple(f"panda_joint{i}" for i in range(1, 8)),
    base_link="panda_link0",
    mount=ScopeMount("panda_link8"),  # +z of panda_link8 is the flange normal
    # Franka Control Interface documentation, "Robot and interface specifications" (the limits libfranka
    # enforces on every command)
    limits=JointLimitTable(
        velocity=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
        acceleration=(15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
        jerk=(7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0),
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
    hardware=True,  # lapwrench.hardware.franka (pylibfranka)
    look=SimLook(rgba=(0.92, 0.92, 0.94, 1.0)),
)
