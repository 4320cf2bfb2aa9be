"""lapwrench.robot.errors: the one error every robot raises when it fails, which the run paths turn
into exit code 3 and one line."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.hardware.franka import FrankaRobot
from lapwrench.robot.errors import RobotError


def test_a_robot_error_is_a_runtime_error() -> None:
    """Code that guards the loop with ``except RuntimeError`` sees robot failures too."""
    assert issubclass(RobotError, RuntimeError)


@pytest.mark.parametrize("call", ["read", "command"])
def test_the_franka_driver_raises_it_before_it_is_connected(call: str) -> None:
    robot = FrankaRobot("192.168.1.2")
    with pytest.raises(RobotError, match=r"^Franka panda at 192\.168\.1\.2: not connected$"):
        robot.read() if call == "read" else robot.command(np.zeros(7))


def test_the_simulated_arm_raises_it_before_it_is_connected() -> None:
    from lapwrench.sim.robot import SimRobot
    from lapwrench.sim.world import SimWorld

    world = SimWorld()
    try:
        robot = SimRobot(world)
        for call in (robot.read, lambda: robot.command(np.zeros(7))):
            with pytest.raises(RobotError, match=r"^simulated panda \(MuJoCo\): not connected$"):
                call()
    finally:
        world.close()
