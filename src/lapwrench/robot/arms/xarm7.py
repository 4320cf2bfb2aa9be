"""UFACTORY xArm7 (7-DoF), simulation only: example-robot-data's ``xarm7.urdf``.

It stands in for the Kinova Gen3 the issue asks for: the Gen3's MJCF comes from mujoco-menagerie,
whose PyPI package downloads the models from GitHub at run time (not possible offline or in a sealed
install), while example-robot-data ships this URDF, which Pinocchio and MuJoCo both load.
"""

from __future__ import annotations

from lapwrench.robot.arms.spec import ArmSpec, JointLimitTable, PackageUrdf, ScopeMount, SimLook

_SPEED = 3.14  # rad/s: xArm7 datasheet, "maximum joint speed 180 deg/s", as the URDF rounds it

SPEC = ArmSpec(
    name="xarm7",
    description=PackageUrdf("example-robot-data", "xarm_description/urdf/xarm7.urdf"),
    joint_names=tuple(f"joint{i}" for i in range(1, 8)),
    base_link="link_base",
    mount=ScopeMount("link7"),  # the flange; +z of link7 leaves it along the tool axis
    limits=JointLimitTable(
        velocity=(_SPEED,) * 7,
        # UFACTORY's SDK caps joint acceleration at 20 rad/s^2; half of it, and the FR3's 5000 rad/s^3
        # jerk (none is published), keep every shaped reference well inside what the drives deliver
        acceleration=(10.0,) * 7,
        jerk=(5000.0,) * 7,
        torque=(50.0, 50.0, 30.0, 30.0, 30.0, 20.0, 20.0),  # the URDF's effort limits (UFACTORY's values)
        torque_rate=(1000.0,) * 7,  # not published: the Franka's 1000 N m/s (the supervisor's check only)
    ),
    # The Panda's simulated start, reached by this arm: flange 0.482 m above the base and 0.5 m in front,
    # scope straight down, {E} turned like the Panda's (so the scene, trocar and view are the same).
    # Found offline by damped least squares on the lap_E pose (scipy least_squares from an elbow-up
    # guess, bounded 0.05 rad inside the limits); every joint is >= 1.6 rad from its limits, the
    # flange Jacobian's smallest singular value is about that of the Panda's start. The controller's
    # home (virtual runs, warm-up) is the same pose.
    home_pose=(0.0, 0.0726, 0.0, 1.4882, 0.0, 1.4155, 0.7854),
    sim_start_pose=(0.0, 0.0726, 0.0, 1.4882, 0.0, 1.4155, 0.7854),
    # simulated joint servo: the Franka's gains (wrists of the UR5 softer, for its 28 N m drives); untuned,
    # they hold the physical RCM within 0.7 mm in the grip scenario
    servo_stiffness=(3000.0, 3000.0, 2500.0, 2500.0, 2000.0, 1500.0, 1500.0),
    servo_damping=(150.0, 150.0, 110.0, 100.0, 40.0, 40.0, 30.0),
    sim_torque_bias=(0.08, -0.1, 0.05, 0.1, -0.02, 0.03, 0.01),
    # the simulated arm takes each command as the servo's reference, held for one 1 ms step; lapwrench
    # still shapes the references within the limits above, as it does for the Franka
    differentiates_commands=False,
    command_period_s=0.001,
    hardware=False,
    look=SimLook(rgba=(0.85, 0.85, 0.85, 1.0), capsule_radius=0.045),
)
