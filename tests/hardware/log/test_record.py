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


def test_each_field_of_a_cycle_record_is_the_cycle_value_it_names() -> None:
    """Every field holds its own source (each a distinct object), none another's: the record is built by
    position, so a field added or moved in :class:`CycleRecord` must not shift the others."""
    import dataclasses

    from lapwrench.controller import TickResult
    from lapwrench.hardware.log.record import CycleRecord
    from lapwrench.sensors import InstrumentObservation, TactileReading

    def v(n: int = 3) -> np.ndarray:
        return np.zeros(n)

    wrenches, telemetry, e_R = {"rcm": v(6)}, {"zoom": (0.5,)}, np.array([3e-4, 4e-4, 0.0])
    r = TickResult(0.4, v(7), v(7), v(7), v(7), wrenches, v(6), e_R, v(), v(), 1.3, 12, "tracking", v(),
                   telemetry=telemetry)
    ft = ForceTorqueReading(v(), v(), 0.45)
    frame = SensorFrame(0.5, ft, TactileReading(v(64), 0.45), InstrumentObservation(np.zeros((1, 2)), 0.4))
    reading = RobotReading(v(7), v(7), v(), 0.501)
    c = Cycle(7, frame, reading, r, MeasuredScope(2e-4, 0.06), v(7), 3e-4, 1e-3, [])  # type: ignore[arg-type]
    tau_J = v(7)
    rec = cycle_record(c, "running", True, tau_J=tau_J)
    sources = {
        "t": 0.5, "robot_time": 0.501, "k": 7, "q": reading.q, "dq": reading.dq, "tau_J": tau_J,
        "external_force": reading.external_force, "ft_force": ft.force, "ft_torque": ft.torque,
        "tactile": frame.tactile.values, "instruments": frame.instruments.points, "wrenches": wrenches,
        "mode": "tracking", "delta": 1.3, "contacts": 12, "p_R": r.p_R, "e_R": e_R, "rcm_error": r.rcm_error,
        "rcm_error_measured": 2e-4, "q_ref": r.q_ref, "q_cmd": c.q_cmd, "supervisor": "running", "alarm": True,
        "compute_us": 3e-4 * 1e6, "cycle_us": 1e-3 * 1e6, "p_G": r.p_G, "telemetry": telemetry,
    }  # fmt: skip
    assert set(sources) == {f.name for f in dataclasses.fields(CycleRecord)}
    for name, source in sources.items():
        got = getattr(rec, name)
        assert got is source if isinstance(source, (np.ndarray, dict)) else got == source, name
