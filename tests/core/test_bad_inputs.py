"""Bad input at the controller's edge never reaches the command."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.robot.limits import limit_usage
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.virtual import DEFAULT_Q0

NAN, INF = float("nan"), float("inf")
GRIP = TactileReading(np.full(64, 62.5))
FT = ForceTorqueReading(np.array([5.0, 0.0, 0.0]), np.zeros(3))
FAR = InstrumentObservation(np.array([[600.0, 400.0]]))


def _frame(t: float, **kw) -> SensorFrame:
    base = {"ft": FT, "tactile": GRIP, "instruments": InstrumentObservation(FAR.points, t)}
    base.update(kw)
    return SensorFrame(t, **base)


BAD = {
    "ft": [
        ForceTorqueReading(np.array([NAN, 0, 0]), np.zeros(3)),
        ForceTorqueReading(np.array([0, INF, 0]), np.zeros(3)),
        ForceTorqueReading(np.array([500.0, 0, 0]), np.zeros(3)),
        ForceTorqueReading(np.zeros(3), np.array([0, 0, 50.0])),
        ForceTorqueReading(np.zeros(2), np.zeros(3)),
        ForceTorqueReading(np.array(["5", "0", "0"]), np.zeros(3)),  # numeric strings are not numbers
        ForceTorqueReading(np.array([5.0 + 1j, 0, 0]), np.zeros(3)),  # complex
        ForceTorqueReading(None, np.zeros(3)),  # type: ignore[arg-type]
        ForceTorqueReading([[5.0, 0.0], [0.0]], np.zeros(3)),  # type: ignore[arg-type]  # ragged
    ],
    "tactile": [
        TactileReading(np.full(64, NAN)),
        TactileReading(np.full(64, 300.0)),
        TactileReading(np.full(64, -1.0)),
        TactileReading(np.full(63, 100.0)),
        TactileReading(np.full(64, True)),  # booleans are not pressures
        TactileReading(["62.5"] * 64),  # type: ignore[arg-type]
    ],
    "instruments": [
        InstrumentObservation(np.array([[NAN, 100.0]])),
        InstrumentObservation(np.array([[INF, 100.0]])),
        InstrumentObservation(np.array([[700.0, 100.0]])),
        InstrumentObservation(np.array([[-5.0, 100.0]])),
        InstrumentObservation(np.array([1.0, 2.0, 3.0])),
        InstrumentObservation([[600.0, 400.0], [100.0]]),  # type: ignore[arg-type]  # ragged
        InstrumentObservation([["600", "400"]]),  # type: ignore[arg-type]
        InstrumentObservation(np.tile([[600.0, 400.0]], (100, 1))),  # 100 at one corner: 1000 N by eq 8
    ],
}
WRENCH_OF = {"ft": "interaction", "tactile": "interaction", "instruments": "tracking"}


@pytest.mark.parametrize(("source", "index"), [(s, i) for s, v in BAD.items() for i in range(len(v))])
def test_bad_reading_zeroes_its_wrench_and_is_reported(source: str, index: int) -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    good = ctrl.tick(_frame(0.0))
    assert np.any(good.wrenches[WRENCH_OF[source]])
    refs = [good.q_ref]
    for k in range(1, 200):
        bad = BAD[source][index]
        if source == "instruments":
            bad = InstrumentObservation(bad.points, k * 1e-3)
        res = ctrl.tick(_frame(k * 1e-3, **{source: bad}))
        assert not np.any(res.wrenches[WRENCH_OF[source]])
        assert any(e.source == source for e in res.events)
        assert np.all(np.isfinite(res.q_ref)) and np.all(np.isfinite(res.tau))
        refs.append(res.q_ref)
    usage = limit_usage(np.array(refs), ctrl.dt, ctrl.model.limits, DEFAULT_Q0)
    assert max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1.0


def test_stale_detection_counts_as_none() -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(1.0, instruments=InstrumentObservation(FAR.points, 0.5)))
    assert not np.any(res.wrenches["tracking"])
    assert any("older" in e.message for e in res.events)


@pytest.mark.parametrize(
    "robot",
    [
        RobotReading(np.full(7, NAN), np.zeros(7), np.zeros(3)),
        RobotReading(DEFAULT_Q0, np.full(7, INF), np.zeros(3)),
        RobotReading(DEFAULT_Q0 + 10.0, np.zeros(7), np.zeros(3)),
        RobotReading(DEFAULT_Q0, np.full(7, 50.0), np.zeros(3)),
        RobotReading(DEFAULT_Q0[:6], np.zeros(7), np.zeros(3)),
    ],
)
def test_bad_robot_state_pauses_adaptation_and_is_reported(robot: RobotReading) -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    p0 = ctrl.rcm.p_R.copy()
    for k in range(100):
        res = ctrl.tick(SensorFrame(k * 1e-3, ft=FT, robot=robot))
        assert any(e.source == "robot" for e in res.events)
        assert np.all(np.isfinite(res.q_ref))
    np.testing.assert_allclose(ctrl.rcm.p_R, p0)


def test_bad_external_force_is_rejected_but_joint_state_kept() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(0.0, ft=FT, robot=RobotReading(DEFAULT_Q0, np.zeros(7), np.array([NAN, 0, 0]))))
    assert any(e.source == "external_force" for e in res.events)


def test_valid_residual_moves_the_rcm_point() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    p0 = ctrl.rcm.p_R.copy()
    wall = np.array([12.0, 0.0, 0.0])
    for k in range(200):
        ctrl.tick(SensorFrame(k * 1e-3, ft=ForceTorqueReading(np.zeros(3), np.zeros(3)),
                              robot=RobotReading(DEFAULT_Q0, np.zeros(7), wall)))
    assert ctrl.rcm.p_R[0] - p0[0] > 1e-3


def test_tick_before_reset_is_an_error() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        Controller(load()).tick(SensorFrame(0.0))


def test_reset_rejects_bad_configuration() -> None:
    ctrl = Controller(load())
    with pytest.raises(ValueError, match="finite"):
        ctrl.reset(np.full(7, NAN))
    with pytest.raises(ValueError, match="limits"):
        ctrl.reset(DEFAULT_Q0 + 5.0)


def test_event_memory_is_bounded_but_every_event_is_counted() -> None:
    from lapwrench.controller import MAX_KEPT_EVENTS

    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    bad = TactileReading(np.full(64, NAN))
    n = MAX_KEPT_EVENTS + 500
    for k in range(n):
        ctrl.tick(SensorFrame(k * 1e-3, tactile=bad))
    assert len(ctrl.events) == MAX_KEPT_EVENTS
    assert ctrl.event_counts["tactile"] == n


@pytest.mark.parametrize("stamp", [None, "0.1", float("nan"), 39.0, -39.0, pytest.param(10**400, id="10**400")])
def test_a_detection_with_a_bad_stamp_is_not_used(stamp: object) -> None:
    """No stamp, a string, NaN, 39 s in the future or in the past, an int beyond any float (raised
    OverflowError, found by the fuzz suite): the detection is dropped with an event."""
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(_frame(0.0, instruments=InstrumentObservation(FAR.points, stamp)))  # type: ignore[arg-type]
    assert not np.any(res.wrenches["tracking"]) and any(e.source == "instruments" for e in res.events)


def test_a_nan_frame_time_uses_no_detection() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(float("nan"), ft=FT, tactile=GRIP, instruments=InstrumentObservation(FAR.points, 0.0)))
    assert not np.any(res.wrenches["tracking"])
