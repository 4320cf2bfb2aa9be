"""lapwrench.hardware.log.record: what one loop cycle hands the logger, and its plain values."""

from __future__ import annotations

import math

import numpy as np

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.hardware.log.record import cycle_record, plain_float, plain_list
from lapwrench.loop_stats import Cycle
from lapwrench.safety.checks import MeasuredScope
from lapwrench.sensors import ForceTorqueReading, RobotReading, SensorFrame
from lapwrench.virtual import home_pose


def _cycle(result: object) -> Cycle:
    q = home_pose("panda")
    frame = SensorFrame(0.5, ForceTorqueReading(np.ones(3), np.zeros(3), 0.5))
    reading = RobotReading(q, np.zeros(7), None, 0.501)
    return Cycle(7, frame, reading, result, MeasuredScope(2e-4, 0.06), q, 3e-4, 1e-3, [])  # type: ignore[arg-type]


def test_a_cycle_record_carries_the_tick_the_measured_scope_and_the_supervisor() -> None:
    ctrl = Controller(load())
    ctrl.reset(home_pose("panda"))
    assert ctrl.ref is not None
    r = ctrl.tick(SensorFrame(0.5, robot=RobotReading(ctrl.ref.q, ctrl.ref.dq, None, 0.5)))
    rec = cycle_record(_cycle(r), "running", False, tau_J=np.zeros(7))
    assert rec is not None
    assert (rec.t, rec.robot_time, rec.k, rec.supervisor, rec.alarm) == (0.5, 0.501, 7, "running", False)
    assert rec.rcm_error_measured == 2e-4 and math.isclose(rec.compute_us, 300.0) and math.isclose(rec.cycle_us, 1e3)
    assert set(rec.wrenches) == set(r.wrenches) and rec.mode == r.mode
    assert rec.ft_force is not None and rec.tactile is None and rec.instruments is None


def test_a_failed_tick_has_no_record() -> None:
    assert cycle_record(_cycle(None), "holding", True) is None


def test_plain_values_have_no_nan() -> None:
    assert plain_list(np.array([1.0, np.nan, np.inf])) == [1.0, None, None] and plain_list(None) is None
    assert plain_float(np.nan) is None and plain_float(2) == 2.0 and plain_float(None) is None


def test_a_cycle_record_carries_the_python_cues_telemetry() -> None:
    """The configured keep-out cue's telemetry rides along by cue name, and reads back by field name
    in a log whose schema names its fields."""
    from lapwrench.config import from_dict

    ctrl = Controller(from_dict({"cues": {"keep_out": {"center": [0.9, 0.0, 0.1], "radius": 0.05}}}))
    ctrl.reset(home_pose("panda"))
    assert ctrl.ref is not None
    r = ctrl.tick(SensorFrame(0.5, robot=RobotReading(ctrl.ref.q, ctrl.ref.dq, None, 0.5)))
    rec = cycle_record(_cycle(r), "running", False)
    assert rec is not None and rec.telemetry is not None and set(rec.telemetry) == {"keep_out"}
    distance, barrier = rec.telemetry["keep_out"]
    got = rec.to_dict((("keep_out", ("distance", "barrier")),))["telemetry"]
    assert got == {"keep_out": {"distance": distance, "barrier": barrier}} and distance > 0.2
    assert rec.to_dict()["telemetry"] == {}  # a log that names no telemetry fields carries none
