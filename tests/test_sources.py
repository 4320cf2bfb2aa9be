"""The one sensor abstraction: simulated observables and hardware buffers behave alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.buffer import LatestValue
from lapwrench.sensors import ForceTorqueReading, InstrumentObservation
from lapwrench.sources import BufferSource, Observable, fresh, ft_reading

DT = 0.001


def _ft(t: float) -> ForceTorqueReading:
    return ForceTorqueReading(np.array([t, 0.0, 0.0]), np.zeros(3), t)


def _run(src: Observable, seconds: float) -> list[ForceTorqueReading | None]:
    out = []
    for k in range(round(seconds / DT)):
        src.poll(k * DT)
        out.append(src.latest())
    return out


def test_observable_samples_at_its_interval_and_delivers_after_its_delay() -> None:
    src = Observable("ft", _ft, update_interval=0.04, delay=0.01, max_age=0.1)
    seen = _run(src, 0.2)
    assert all(r is None for r in seen[:10])  # the first sample (t = 0) arrives at 10 ms
    stamps = sorted({r.stamp for r in seen if r is not None})
    np.testing.assert_allclose(stamps, [0.0, 0.04, 0.08, 0.12, 0.16], atol=1e-9)
    # at t = 0.05 the newest arrived sample is the one taken at 0.04 (arrived at 0.05)
    assert seen[50] is not None and seen[50].stamp == pytest.approx(0.04)
    assert seen[49] is not None and seen[49].stamp == pytest.approx(0.0)


def test_corruptor_sees_every_sample_and_can_drop_it() -> None:
    def drop_odd(r: ForceTorqueReading, rng: np.random.Generator) -> ForceTorqueReading | None:
        return None if round(r.stamp / 0.01) % 2 else ForceTorqueReading(r.force + 1.0, r.torque, r.stamp)

    src = Observable("ft", _ft, update_interval=0.01, max_age=0.1, corruptor=drop_odd)
    stamps = {round(r.stamp, 3) for r in _run(src, 0.1) if r is not None}
    assert stamps == {0.0, 0.02, 0.04, 0.06, 0.08}
    last = src.latest()
    assert last is not None and last.force[0] == pytest.approx(last.stamp + 1.0)


def test_fresh_rejects_old_future_and_nan_stamps() -> None:
    src = Observable("ft", _ft, update_interval=0.01, max_age=0.02)
    src.poll(0.0)
    assert fresh(src, 0.0) is not None
    assert fresh(src, 0.02) is not None
    assert fresh(src, 0.021) is None  # too old
    nan = Observable("ft", lambda t: ForceTorqueReading(np.zeros(3), np.zeros(3), math.nan),
                     update_interval=0.01, max_age=0.02)
    nan.poll(0.0)
    assert fresh(nan, 0.0) is None
    future = Observable("ft", lambda t: ForceTorqueReading(np.zeros(3), np.zeros(3), t + 5.0),
                        update_interval=0.01, max_age=0.02)
    future.poll(0.0)
    assert fresh(future, 0.0) is None


@pytest.mark.parametrize(
    "kwargs", [{"update_interval": 0.0}, {"update_interval": -1.0}, {"update_interval": math.nan},
               {"delay": -0.01}, {"max_age": 0.0}, {"max_age": math.inf}, {"max_age": "0.1"}]
)
def test_bad_parameters_are_refused(kwargs: dict[str, object]) -> None:
    args: dict[str, object] = {"update_interval": 0.01, "max_age": 0.1, **kwargs}
    with pytest.raises(ValueError):
        Observable("ft", _ft, **args)  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["GPS", "a b", "", 5, None, "x\n"])
def test_a_kind_that_is_no_input_name_is_refused(kind: object) -> None:
    with pytest.raises(ValueError, match="kind"):
        Observable(kind, _ft, update_interval=0.01, max_age=0.1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="kind"):
        BufferSource(kind, LatestValue(), ft_reading, max_age=0.1)  # type: ignore[arg-type]


def test_a_registered_input_name_is_a_kind() -> None:
    assert Observable("gps", _ft, update_interval=0.01, max_age=0.1).kind == "gps"


def test_buffer_source_converts_and_stamps_in_session_time() -> None:
    class W:
        force = np.array([1.0, 2.0, 3.0])
        torque = np.zeros(3)

    buf: LatestValue[W] = LatestValue("ft")
    src = BufferSource("ft", buf, ft_reading, max_age=0.02)
    src.t0 = 100.0
    assert src.latest() is None
    buf.put(W(), timestamp=100.5)
    r = src.latest()
    assert isinstance(r, ForceTorqueReading) and r.stamp == pytest.approx(0.5)
    np.testing.assert_array_equal(r.force, [1.0, 2.0, 3.0])
    assert fresh(src, 0.51) is not None and fresh(src, 0.53) is None


def test_an_empty_detection_is_a_reading_not_an_absence() -> None:
    src = Observable("instruments", lambda t: InstrumentObservation(np.zeros((0, 2)), t), update_interval=0.04,
                     max_age=0.2)
    src.poll(0.0)
    r = fresh(src, 0.0)
    assert r is not None and r.points.shape == (0, 2)


def test_without_delay_each_sample_is_the_latest_at_once_and_in_order() -> None:
    src = Observable("ft", _ft, update_interval=DT, max_age=0.1)
    for k in range(5):
        src.poll(k * DT)
        assert src.latest() is not None and src.latest().stamp == k * DT
    late = Observable("ft", _ft, update_interval=DT, delay=0.003, max_age=0.1)
    stamps = []
    for k in range(10):
        if k == 4:
            late.delay = 0.0  # the samples in flight still arrive first
        late.poll(k * DT)
        r = late.latest()
        stamps.append(None if r is None else round(r.stamp / DT))
    assert stamps == [None, None, None, 0, 1, 2, 6, 7, 8, 9]  # first in, first out, then straight through
