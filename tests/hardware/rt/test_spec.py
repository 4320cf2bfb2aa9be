"""lapwrench.hardware.rt.spec: what the parent hands the spawned real-time child (it must pickle) and
how the child's failure reaches the command line (a robot error)."""

from __future__ import annotations

import pickle
from typing import Any

from lapwrench.hardware.rt.options import RtOptions
from lapwrench.hardware.rt.spec import FtSpec, RtProcessError, RtSpec
from lapwrench.hardware.runner import SourceAges
from lapwrench.robot.errors import RobotError
from lapwrench.safety.supervisor import SupervisorConfig


def make_robot(cfg: Any, script: Any) -> str:
    """A module-level factory, as the child needs (a lambda would not pickle)."""
    return f"robot for {cfg}"


def test_a_spec_crosses_to_a_spawned_process_intact() -> None:
    spec = RtSpec(cfg="cfg", robot_factory=make_robot, supervisor=SupervisorConfig(),
                  ft=FtSpec("hex", "192.168.1.1", 49152), inputs=(("pedal", (1,), 0.1),), duration=2.0)
    back = pickle.loads(pickle.dumps(spec))
    assert back.ft == FtSpec("hex", "192.168.1.1", 49152, tare=True, tare_samples=100)
    assert back.robot_factory(back.cfg, None) == "robot for cfg" and back.duration == 2.0
    assert back.inputs == spec.inputs and back.rt == RtOptions()


def test_the_input_slots_are_the_registered_inputs_names_and_shapes() -> None:
    spec = RtSpec(cfg=None, robot_factory=make_robot, supervisor=SupervisorConfig(),
                  inputs=(("pedal", (1,), 0.1), ("gaze", (2, 3), 0.05)))
    assert spec.input_slots == (("pedal", (1,)), ("gaze", (2, 3)))
    assert RtSpec(cfg=None, robot_factory=make_robot, supervisor=SupervisorConfig()).input_slots == ()


def test_the_defaults_log_every_cycle_with_tactile_and_no_camera() -> None:
    spec = RtSpec(cfg=None, robot_factory=make_robot, supervisor=SupervisorConfig())
    assert spec.log_cycles and spec.tactile and not spec.instruments and spec.ft is None
    assert spec.ages == SourceAges() and (spec.log_rows, spec.event_rows) == (4096, 1024)


def test_a_failed_child_is_a_robot_error_for_the_command_line() -> None:
    """The run paths catch RobotError (exit code, one line): the child's failures are among them."""
    try:
        raise RtProcessError("real-time process exited with code -9")
    except RobotError as exc:
        assert str(exc) == "real-time process exited with code -9"
