"""lapwrench.hardware.rt.factories: the robots the real-time child builds from ``RtSpec.robot_factory``.

The factories travel to a spawned process, so their partials must pickle; the Franka factory maps the
configuration onto the driver (nothing connects until the loop starts), and the simulated one drives
the handle with the dry-run script's hand force on the script's own clock.
"""

from __future__ import annotations

import functools
import pickle
import time
from typing import Any

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.hardware.devices import DryRunScript
from lapwrench.hardware.franka import FrankaRobot, Payload
from lapwrench.hardware.rt.factories import franka_factory, sim_factory
from lapwrench.robot.description import ScopeGeometry
from lapwrench.sim.robot import SimRobot
from lapwrench.virtual import home_pose


class PushScript:
    """A dry-run script whose hand force is a fixed push, counting how often it was asked."""

    def __init__(self, force: tuple[float, float, float]) -> None:
        self.force = np.array(force)
        self.asked = 0

    def force_H(self) -> np.ndarray:
        self.asked += 1
        return self.force.copy()


def test_the_factories_pickle_for_the_spawned_child() -> None:
    for factory in (functools.partial(sim_factory, realtime=True),
                    functools.partial(franka_factory, robot_ip="10.0.0.2", kind="fr3", realtime="ignore")):
        back = pickle.loads(pickle.dumps(factory))
        assert back.func is factory.func and back.keywords == factory.keywords


@pytest.mark.parametrize("cfg_name", ["panda_cfg", "fr3_cfg"])
def test_franka_factory_maps_the_configuration_onto_the_driver(cfg_name: str, request: pytest.FixtureRequest) -> None:
    cfg: Config = request.getfixturevalue(cfg_name)
    robot = franka_factory(cfg, None, robot_ip="192.0.2.7", kind=cfg.robot.kind, realtime="ignore",
                           ext_wrench_sign="environment_on_robot", report_external_force=False)
    assert isinstance(robot, FrankaRobot)
    assert robot.robot_ip == "192.0.2.7" and robot.kind == cfg.robot.kind and robot.realtime == "ignore"
    assert robot.ext_wrench_sign == "environment_on_robot" and not robot.report_external_force
    assert robot.dt == cfg.robot.dt
    assert robot.state is None  # built, not connected
    assert robot.load == Payload.from_scope(ScopeGeometry.from_config(cfg.scope))  # the laparoscope on the flange
    assert robot.load is not None and robot.load.mass > 0.0
    assert franka_factory(cfg, None, robot_ip="192.0.2.7", kind=cfg.robot.kind, payload=False).load is None


@pytest.mark.parametrize(("kw", "words"), [({"kind": "ur5"}, "robot kind"), ({"realtime": "sometimes"}, "realtime"),
                                           ({"ext_wrench_sign": "up"}, "ext_wrench_sign")])
def test_franka_factory_refuses_what_the_driver_refuses(panda_cfg: Config, kw: dict[str, Any], words: str) -> None:
    args: dict[str, Any] = {"robot_ip": "192.0.2.7", "kind": "panda", **kw}
    with pytest.raises(ValueError, match=words):
        franka_factory(panda_cfg, None, **args)


def test_franka_factory_needs_the_address_and_the_kind(panda_cfg: Config) -> None:
    with pytest.raises(TypeError):
        franka_factory(panda_cfg, None)  # type: ignore[call-arg]


def test_sim_factory_pushes_the_handle_with_the_scripts_force_on_the_scripts_clock(panda_cfg: Config) -> None:
    script = PushScript((6.0, -1.0, 0.5))
    q0 = home_pose("panda") + 0.01
    robot = sim_factory(panda_cfg, script, realtime=False, q0=q0)
    try:
        assert isinstance(robot, SimRobot) and robot.kind == "panda" and not robot.realtime
        np.testing.assert_array_equal(robot.q0, q0)
        assert robot.hand_force_H is not None
        for robot_time in (0.0, 3.0, 1e6):  # the robot's time is ignored: the script has its own clock
            np.testing.assert_array_equal(robot.hand_force_H(robot_time), script.force)
        assert script.asked == 3
        script.force[:] = 0.0
        assert not np.any(robot.hand_force_H(0.0))  # asked each time, not copied once
        reading = robot.connect()
        np.testing.assert_allclose(reading.q, q0, atol=1e-9)  # it starts where it was told
    finally:
        robot.world.close()


def test_sim_factory_without_a_script_leaves_the_handle_alone(fr3_cfg: Config) -> None:
    robot = sim_factory(fr3_cfg, None)
    try:
        assert robot.kind == "fr3" and robot.realtime  # the configured arm; paced to the wall clock by default
        assert robot.hand_force_H is None and robot.q0 is None
    finally:
        robot.world.close()


def test_sim_factory_takes_the_dry_run_script(panda_cfg: Config) -> None:
    """The script ``lapwrench run --dry-run`` shares with the child: untouched during the tare, then pushed."""
    script = DryRunScript(t0=0.0)
    robot = sim_factory(panda_cfg, script, realtime=False)
    try:
        assert robot.hand_force_H is not None
        script.t0 = time.monotonic() - 2.0  # 2 s into the script: the first push
        np.testing.assert_array_equal(robot.hand_force_H(0.0), script.pushes[0][2])
        script.t0 = time.monotonic()  # at its start: the tare, no force
        assert not np.any(robot.hand_force_H(0.0))
    finally:
        robot.world.close()
