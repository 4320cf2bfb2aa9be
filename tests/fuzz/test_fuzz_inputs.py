"""Property-based fuzzing of the controller's input edge (issue 11): ``InputValidator`` and ``Controller.tick``.

Every sensor field is drawn from a mix of plausible readings and junk: NaN, inf, huge and negative
numbers, strings (numeric ones too), complex values, ``None``, booleans, ragged and nested lists,
object arrays, arrays of the wrong shape or dtype, non-contiguous views, stamps far in the future or
past. The properties:

* the validator never raises; what it accepts is a finite float64 array of the right shape inside
  its range, and every present reading is either accepted or rejected with an event for its source;
* ``Controller.tick`` never raises on any such frame; the joint reference stays finite, moves by at
  most the robot's velocity limit x dt per tick, a rejected reading's wrench is zero, and every
  rejection is counted once in ``event_counts``.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.sensors import (
    TACTILE_ELEMENTS,
    TACTILE_MAX,
    ForceTorqueReading,
    InputValidator,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.virtual import DEFAULT_Q0

SOURCES = ("ft", "tactile", "instruments", "robot", "external_force")
WIDTH, HEIGHT = 640, 480  # the default camera (checked in the fixture)

# -- strategies ------------------------------------------------------------------------------------

any_float = st.floats(allow_nan=True, allow_infinity=True)
numeric_string = st.one_of(st.floats(allow_nan=True).map(str), st.integers(-1000, 1000).map(str))
junk_scalar = st.one_of(
    any_float,
    st.integers(),
    st.sampled_from([10**400, -(10**400), 2**63, 2**64]),  # do not fit a float / an int64
    st.booleans(),
    st.complex_numbers(max_magnitude=1e6),
    st.none(),
    st.text(max_size=4),
    numeric_string,
    st.sampled_from([np.float32(1.5), np.int64(3), np.bool_(True), np.complex64(1j), np.float64("nan")]),
)
junk_dtype = st.sampled_from(
    [np.float64, np.float32, np.float16, np.longdouble, np.int64, np.int8, np.uint64, np.bool_, np.complex128,
     "U4", "S3", "M8[s]", object]
)


def junk_array(side: int) -> st.SearchStrategy[Any]:
    """Arrays of any dtype and of a shape near the expected one (side +-1, other ranks)."""
    shape = st.one_of(
        hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=side + 1),
        st.sampled_from([(side,), (side - 1,), (side + 1,), (side, 1), (1, side)]),
    )
    return junk_dtype.flatmap(lambda dt: hnp.arrays(dt, shape))


def junk(side: int) -> st.SearchStrategy[Any]:
    """Anything but a sensible reading of ``side`` elements."""
    lists = st.lists(junk_scalar, min_size=max(side - 1, 0), max_size=side + 1)
    return st.one_of(
        junk_scalar,
        junk_array(side),
        lists,
        lists.map(lambda v: np.array(v, dtype=object)),
        st.lists(st.one_of(junk_scalar, lists), min_size=1, max_size=3),  # nested / ragged
        st.just([[1.0, 2.0], [3.0]]),
    )


def vector(n: int, lo: float, hi: float) -> st.SearchStrategy[Any]:
    """A plausible reading (float/int array, list or a non-contiguous view), a wild float one, or junk."""
    good = hnp.arrays(np.float64, (n,), elements=st.floats(lo, hi))
    wild = hnp.arrays(np.float64, (n,), elements=any_float)
    return st.one_of(
        good,
        good.map(list),
        good.map(lambda a: np.repeat(a, 2)[::2]),  # a strided view
        good.map(lambda a: a.astype(np.float32)),
        hnp.arrays(np.int64, (n,), elements=st.integers(int(lo), int(hi))),
        wild,
        junk(n),
    )


def points() -> st.SearchStrategy[Any]:
    """Instrument image points: in the image, anywhere, too many, or junk."""
    inside = st.tuples(st.floats(0, WIDTH), st.floats(0, HEIGHT)).map(list)
    anywhere = st.tuples(any_float, any_float).map(list)
    return st.one_of(
        st.lists(inside, min_size=0, max_size=4).map(lambda p: np.array(p, dtype=np.float64).reshape(-1, 2)),
        st.lists(st.one_of(inside, anywhere), min_size=0, max_size=12),
        st.integers(0, 200).map(lambda n: np.tile([[600.0, 400.0]], (n, 1))),  # many detections at one corner
        junk(2),
    )


def stamp(now: float) -> st.SearchStrategy[Any]:
    """A stamp near ``now``, far from it, not finite, huge, or not a number at all."""
    return st.one_of(
        st.floats(-0.05, 0.05).map(lambda d: now + d),
        st.sampled_from([now, now - 39.0, now + 39.0, 1e300, -1e300, 10**400, -(10**400)]),
        any_float,
        st.integers(),
        st.sampled_from([None, "0.1", True, 1j, np.float32(now), np.int64(0), np.datetime64(0, "s")]),
    )


@st.composite
def frames(draw: st.DrawFn, now: float) -> SensorFrame:
    """A sensor frame at ``now`` whose every field may be missing, valid or junk."""
    maybe = st.booleans()
    ft = tactile = instruments = robot = None
    if draw(maybe):
        ft = ForceTorqueReading(draw(vector(3, -40.0, 40.0)), draw(vector(3, -3.0, 3.0)), draw(stamp(now)))
    if draw(maybe):
        tactile = TactileReading(draw(vector(TACTILE_ELEMENTS, 0.0, TACTILE_MAX)), draw(stamp(now)))
    if draw(maybe):
        instruments = InstrumentObservation(draw(points()), draw(stamp(now)))
    if draw(maybe):
        q = draw(st.one_of(vector(7, -0.01, 0.01).map(lambda d: DEFAULT_Q0 + d if isinstance(d, np.ndarray) and
                                                      d.shape == (7,) and d.dtype.kind == "f" else d)))
        ext = draw(st.one_of(st.none(), vector(3, -20.0, 20.0)))
        robot = RobotReading(q, draw(vector(7, -0.5, 0.5)), ext, draw(stamp(now)))
    return SensorFrame(now, ft, tactile, instruments, robot)


frame_times = st.one_of(st.floats(0.0, 10.0), st.sampled_from([float("nan"), float("inf"), -float("inf"), -1.0]))

# -- fixtures --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def controller() -> Controller:
    """One controller for the module (construction compiles/loads the tick); reset per example."""
    ctrl = Controller(load())
    assert (ctrl.cfg.camera.width, ctrl.cfg.camera.height) == (WIDTH, HEIGHT)
    return ctrl


# -- the validator ---------------------------------------------------------------------------------


def _check_accepted(validator: InputValidator, frame: SensorFrame, out: Any) -> None:
    """What passed is finite float64 of the right shape and in range; what did not is reported."""
    sources = Counter(e.source for e in out.events)
    for name in ("ft", "tactile", "robot"):
        present, accepted = getattr(frame, name) is not None, getattr(out, name)
        assert not (accepted is not None and sources[name]), f"{name} both accepted and rejected"
        assert (not present) or accepted is not None or sources[name], f"{name} neither accepted nor rejected"
        assert present or accepted is None
    if out.ft is not None:
        for v in (out.ft.force, out.ft.torque):
            assert v.dtype == np.float64 and v.shape == (3,) and np.isfinite(v).all()
        assert np.linalg.norm(out.ft.force) <= validator.interaction.force_range
        assert np.linalg.norm(out.ft.torque) <= validator.interaction.torque_range
    if out.tactile is not None:
        v = out.tactile.values
        assert v.dtype == np.float64 and v.shape == (TACTILE_ELEMENTS,) and np.isfinite(v).all()
        assert v.min() >= 0.0 and v.max() <= TACTILE_MAX
    if out.robot is not None:
        for v in (out.robot.q, out.robot.dq):
            assert v.dtype == np.float64 and v.shape == (7,) and np.isfinite(v).all()
        ext = out.robot.external_force
        assert ext is None or (ext.shape == (3,) and np.isfinite(ext).all())
    if frame.instruments is not None:
        assert (out.instruments is not None) + (sources["instruments"] > 0) == 1, "instruments: accepted xor rejected"
    if out.instruments is not None:
        p = out.instruments.points
        assert p.dtype == np.float64 and p.ndim == 2 and p.shape[1] == 2 and np.isfinite(p).all()
        assert len(p) <= validator.max_instruments
        assert (p >= 0).all() and (p[:, 0] <= WIDTH).all() and (p[:, 1] <= HEIGHT).all()
        s = out.instruments.stamp
        assert isinstance(s, float | int | np.floating | np.integer) and not isinstance(s, bool | np.bool_)
        assert math.isfinite(float(s)) and abs(frame.time - float(s)) <= validator.max_image_age
    assert set(sources) <= set(SOURCES)


@settings(max_examples=250)
@given(frame_times.flatmap(frames))
@example(SensorFrame(0.0, instruments=InstrumentObservation(np.array([[1.0, 1.0]]), 10**400)))  # OverflowError
def test_validator_accepts_only_sound_readings(controller: Controller, frame: SensorFrame) -> None:
    validator = controller.validator
    out = validator.validate(frame)
    _check_accepted(validator, frame, out)


# -- the tick --------------------------------------------------------------------------------------


@settings(max_examples=120)
@given(st.data())
def test_tick_never_raises_and_the_reference_never_jumps(controller: Controller, data: st.DataObject) -> None:
    ctrl = controller
    ctrl.reset(DEFAULT_Q0)
    step_max = ctrl.model.limits.velocity * ctrl.dt * (1.0 + 1e-9) + 1e-12
    q_prev = DEFAULT_Q0.copy()
    seen: Counter[str] = Counter()
    t0 = data.draw(st.floats(0.0, 10.0))
    for k in range(data.draw(st.integers(1, 4))):
        now = data.draw(st.one_of(st.just(t0 + k * ctrl.dt), frame_times))
        frame = data.draw(frames(now))
        res = ctrl.tick(frame)
        assert np.isfinite(res.q_ref).all() and np.isfinite(res.dq_ref).all() and np.isfinite(res.tau).all()
        assert (np.abs(res.q_ref - q_prev) <= step_max).all(), "the joint reference jumped"
        q_prev = res.q_ref
        by_source = Counter(e.source for e in res.events)
        seen.update(by_source)
        if frame.instruments is not None and by_source["instruments"]:
            assert not np.any(res.wrenches["tracking"]), "a rejected detection drove the tracking wrench"
        if frame.ft is None or by_source["ft"]:
            assert not np.any(res.wrenches["interaction"]), "no valid F/T, yet a handle wrench"
        for w in res.wrenches.values():
            assert np.isfinite(w).all()
    for source in SOURCES:
        assert ctrl.event_counts[source] == seen[source], f"{source} events miscounted"
