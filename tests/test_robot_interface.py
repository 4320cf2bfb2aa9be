"""lapwrench.robot_interface: the one protocol every robot the loop drives implements (the virtual
model, the MuJoCo arm, the Franka), checked at run time; a driver missing a method is not one."""

from __future__ import annotations

import numpy as np

from lapwrench.config import load
from lapwrench.hardware.franka import FrankaRobot
from lapwrench.robot_interface import RobotInterface
from lapwrench.sensors import RobotReading
from lapwrench.virtual import VirtualRobot, home_pose, run_virtual


class Incomplete:
    """A would-be driver without ``command``."""

    kind = "panda"
    dt = 0.001

    def connect(self) -> RobotReading:
        return RobotReading(np.zeros(7), np.zeros(7), None, 0.0)

    def read(self) -> RobotReading:
        return self.connect()

    def disconnect(self) -> None:
        pass


def test_the_shipped_robots_are_robot_interfaces() -> None:
    assert isinstance(VirtualRobot("panda", home_pose("panda"), 0.001), RobotInterface)
    assert isinstance(FrankaRobot("192.168.1.2"), RobotInterface)  # nothing connects before connect()


def test_a_driver_missing_a_method_is_not_one() -> None:
    assert not isinstance(Incomplete(), RobotInterface)


def test_the_virtual_robot_reads_back_what_it_was_commanded() -> None:
    """The protocol's cycle: read, command one reference, read it back one period later."""
    robot = VirtualRobot("ur5", home_pose("ur5"), 0.001)
    first = robot.connect()
    q = first.q + 1e-3
    robot.command(q)
    now = robot.read()
    np.testing.assert_allclose(now.q, q)
    np.testing.assert_allclose(now.dq, np.full(6, 1.0))  # 1 mrad over 1 ms
    assert now.stamp == 0.001 and now.external_force is None
    robot.disconnect()


def test_one_loop_drives_a_robot_through_the_interface_alone() -> None:
    """run_virtual drives its robot only through the protocol: the 6-joint UR5 as well as the Panda."""
    cfg = load().replace(robot={"kind": "ur5"})
    _, log = run_virtual(cfg, 0.05)
    assert log.alarm is None and log.array("q_ref").shape[1] == 6
