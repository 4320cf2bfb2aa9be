"""The input validator: valid readings pass as they are, converted to aligned C-contiguous float64."""

from __future__ import annotations

import pickle
from collections.abc import Callable

import numpy as np
import pytest
from helpers import unaligned

from lapwrench.config import load
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import (
    ForceTorqueReading,
    InputValidator,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.virtual import DEFAULT_Q0


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


# -- the validator -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def validator(model: RobotModel) -> InputValidator:
    cfg = load()
    return InputValidator(cfg.interaction, cfg.camera, model.limits, cfg.inputs.max_image_age)


def _frame(make: Callable[..., object] = np.array) -> SensorFrame:
    return SensorFrame(
        1.0,
        ForceTorqueReading(make([1.0, 2.0, 3.0]), make([0.1, 0.0, 0.0]), 1.0),
        TactileReading(make(np.full(64, 60.0)), 1.0),
        InstrumentObservation(make(np.array([[100.0, 200.0], [300.0, 50.0]])), 1.0),
        RobotReading(make(DEFAULT_Q0.copy()), make(np.zeros(7)), make([5.0, 0.0, 0.0]), 1.0),
    )


def _arrays(out: object) -> list[np.ndarray]:
    readings = (out.ft, out.tactile, out.instruments, out.robot)  # type: ignore[attr-defined]
    return [v for r in readings for v in vars(r).values() if isinstance(v, np.ndarray)]


def test_valid_readings_pass_on_as_they_are(validator: InputValidator) -> None:
    frame = _frame()
    out = validator.validate(frame)
    assert out.events == []
    assert out.ft is frame.ft and out.tactile is frame.tactile
    assert out.instruments is frame.instruments and out.robot is frame.robot


def test_readings_with_an_equal_float64_dtype_of_their_own_pass_on_as_they_are(validator: InputValidator) -> None:
    """Arrays from numba's cached kernels (the controller's reference, fed back as the robot reading) carry a
    float64 dtype equal to numpy's but not the same object, as an unpickled dtype does: passed on as they are,
    not converted every tick."""
    own = pickle.loads(pickle.dumps(np.dtype(np.float64)))

    def make(values: object) -> np.ndarray:
        a = np.empty(np.shape(values), dtype=own)
        a[...] = values
        return a

    frame = _frame(make)
    assert all(a.dtype is own for a in _arrays(frame)) and own is not np.dtype(np.float64) and own == np.float64
    out = validator.validate(frame)
    assert out.events == []
    assert out.ft is frame.ft and out.tactile is frame.tactile
    assert out.instruments is frame.instruments and out.robot is frame.robot


@pytest.mark.parametrize("make", [list, unaligned, lambda v: np.asarray(v, dtype=np.float32),
                                  lambda v: np.repeat(v, 2, axis=0)[::2]],
                         ids=["lists", "unaligned", "float32", "strided"])
def test_converted_readings_hold_aligned_c_contiguous_float64(
    validator: InputValidator, make: Callable[[np.ndarray], object]
) -> None:
    out = validator.validate(_frame(lambda v: make(np.array(v, dtype=np.float64))))
    assert out.events == []
    arrays = _arrays(out)
    assert len(arrays) == 7  # F/T 2, tactile, points, robot 3
    for a in arrays:
        assert a.dtype == np.float64 and a.flags.c_contiguous and a.flags.aligned
    plain = validator.validate(_frame(lambda v: np.array(make(np.array(v, dtype=np.float64)), dtype=np.float64)))
    want = _arrays(plain)
    for a, b in zip(arrays, want, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_rejected_external_force_keeps_the_joint_state(validator: InputValidator) -> None:
    frame = _frame()
    robot = frame.robot
    assert robot is not None
    bad = SensorFrame(1.0, robot=RobotReading(robot.q, robot.dq, np.array([400.0, 0.0, 0.0]), 1.0))
    out = validator.validate(bad)
    assert [e.source for e in out.events] == ["external_force"]
    assert out.robot is not None and out.robot.external_force is None and out.robot.q is robot.q


def test_each_rejected_reading_has_its_event_in_reading_order(validator: InputValidator) -> None:
    """One compiled call checks every value of the frame; the verdicts still come reading by reading."""
    frame = SensorFrame(
        1.0,
        ForceTorqueReading(np.array([np.nan, 0.0, 0.0]), np.zeros(3), 1.0),
        TactileReading(np.full(64, 300.0), 1.0),
        InstrumentObservation(np.array([[1e5, 0.0]]), 1.0),
        RobotReading(DEFAULT_Q0.copy(), np.full(7, 100.0), np.zeros(3), 1.0),
    )
    out = validator.validate(frame)
    assert [e.source for e in out.events] == ["ft", "tactile", "instruments", "robot"]
    assert out.ft is None and out.tactile is None and out.instruments is None and out.robot is None
    assert "not finite" in out.events[0].message and "outside [0, 255]" in out.events[1].message
    assert "outside the" in out.events[2].message and "velocity" in out.events[3].message


@pytest.mark.parametrize(
    ("frame", "source", "words"),
    [
        (SensorFrame(1.0, instruments=InstrumentObservation(np.zeros((10**6, 2), dtype=np.int64), 1.0)),
         "instruments", "1000000 detections"),
        (SensorFrame(1.0, instruments=InstrumentObservation([[1, 2]] * 10**6, 1.0)),
         "instruments", "1000000 detections"),
        (SensorFrame(1.0, instruments=InstrumentObservation(np.zeros((2, 10**6)), 1.0)), "instruments", "(n, 2)"),
        (SensorFrame(1.0, tactile=TactileReading(list(range(10**6)), 1.0)), "tactile", "64 elements"),
        (SensorFrame(1.0, ft=ForceTorqueReading(np.zeros(10**6, dtype=np.int32), np.zeros(3), 1.0)), "ft", "3-vectors"),
    ],
)
def test_a_huge_reading_is_refused_before_it_is_converted(
    validator: InputValidator, frame: SensorFrame, source: str, words: str
) -> None:
    """The size is checked first: converting a million detections (16 MB of float64) inside the tick
    cost 29 ms before it was refused; now nothing that size is allocated."""
    import tracemalloc

    tracemalloc.start()
    try:
        out = validator.validate(frame)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [e.source for e in out.events] == [source] and words in out.events[0].message
    assert peak < 1_000_000
