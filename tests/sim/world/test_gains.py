"""The simulated arm's joint servo gains."""

from __future__ import annotations

import pytest

from lapwrench.robot.description import ARM_SPECS
from lapwrench.sim.scene.build import Scene
from lapwrench.sim.world import JointServoGains, SimWorld


def test_the_servo_gains_are_the_robots_and_one_per_joint(panda_scene: Scene) -> None:
    spec = ARM_SPECS["panda"]
    w = SimWorld(panda_scene)
    assert w.n_joints == spec.n_joints and w.gains == JointServoGains.for_robot("panda")
    act = [w.model.actuator(f"servo_{n}").id for n in w.scene.arm_joint_names]
    assert w.model.actuator_gainprm[act, 0].tolist() == list(spec.servo_stiffness)
    short = JointServoGains(stiffness=spec.servo_stiffness[:-1], damping=spec.servo_damping[:-1])
    with pytest.raises(ValueError, match=f"{spec.n_joints} joints"):
        SimWorld(panda_scene, gains=short)
    with pytest.raises(ValueError, match="differ in length"):
        JointServoGains(stiffness=spec.servo_stiffness, damping=spec.servo_damping[:-1])
