"""Universal Robots UR5 (CB3, 6-DoF), simulation only: example-robot-data's ``ur5_robot.urdf``.

It stands in for the UR5e the issue asks for: the UR5e's MJCF comes from mujoco-menagerie, whose PyPI
package downloads the models from GitHub at run time (not possible offline or in a sealed install),
while example-robot-data ships this URDF, which Pinocchio and MuJoCo both load.
"""

from __future__ import annotations

import math

from lapwrench.robot.arms.spec import ArmSpec, JointLimitTable, PackageUrdf, ScopeMount, SimLook

_SPEED = math.pi  # rad/s: UR5 (CB3) technical specifications, "joint speed: all joints 180 deg/s"

SPEC = ArmSpec(
    name="ur5",
    description=PackageUrdf("example-robot-data", "ur_description/urdf/ur5_robot.urdf"),
    joint_names=(
        "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
    ),
    base_link="base_link",
    mount=ScopeMount("tool0"),  # ROS-Industrial tool flange: +z leaves the flange along the tool axis
    limits=JointLimitTable(
        velocity=(_SPEED,) * 6,
        # UR publishes no joint acceleration or jerk limit (its controller plans within its own); these
        # are conservative choices: 10 rad/s^2 and 5000 rad/s^3 (the FR3's), well below what the UR5's
        # drives deliver, so every reference the shaper makes is one the arm can follow
        acceleration=(10.0,) * 6,
        jerk=(5000.0,) * 6,
        # UR5 (CB3) joint torques: base, shoulder, elbow 150 N m, wrists 28 N m (also the URDF's efforts)
        torque=(150.0, 150.0, 150.0, 28.0, 28.0, 28.0),
        # not published: the Franka's 1000 N m/s (the supervisor's torque-rate check only)
        torque_rate=(1000.0,) * 6,
    ),
    # The Panda's simulated start, reached by this arm: flange 0.482 m above the base and 0.5 m in front,
    # scope straight down, {E} turned like the Panda's (so the scene, trocar and view are the same).
    # Found offline by damped least squares on the lap_E pose (scipy least_squares from an elbow-up
    # guess, bounded 0.05 rad inside the limits); every joint is >= 1.6 rad from its limits, the
    # flange Jacobian's smallest singular value is about that of the Panda's start. The controller's
    # home (virtual runs, warm-up) is the same pose.
    home_pose=(-0.2201, -1.5608, 1.4325, -1.4426, -1.5708, -1.0055),
    sim_start_pose=(-0.2201, -1.5608, 1.4325, -1.4426, -1.5708, -1.0055),
    # simulated joint servo: the Franka's gains (wrists of the UR5 softer, for its 28 N m drives); untuned,
    # they hold the physical RCM within 0.7 mm in the grip scenario
    servo_stiffness=(3000.0, 3000.0, 3000.0, 1500.0, 1500.0, 1500.0),
    servo_damping=(150.0, 150.0, 110.0, 40.0, 40.0, 30.0),
    sim_torque_bias=(0.08, -0.1, 0.05, 0.03, -0.02, 0.01),
    # the simulated arm takes each command as the servo's reference, held for one 1 ms step; lapwrench
    # still shapes the references within the limits above, as it does for the Franka
    differentiates_commands=False,
    command_period_s=0.001,
    hardware=False,
    look=SimLook(rgba=(0.62, 0.72, 0.82, 1.0), capsule_radius=0.05),
)
