"""The Python glue around the compiled tick: Pinocchio's results handed over without conversions
per tick, the validator's common path, and the argument types the bound kernels rely on.

The bound entry points (:func:`lapwrench.jit.bind`) do not check their arguments' types, so every
array reaching them must be C-contiguous, aligned float64 of the bound shape; these tests pin that.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.robot.description import FRAME_E
from lapwrench.robot.model import RobotModel, scope_axis
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


def _reference_terms(model: RobotModel, q: np.ndarray, dq: np.ndarray) -> list[np.ndarray]:
    """What Pinocchio gives at (q, dq), converted the plain way, on a workspace of its own."""
    m, d = model.model, model.model.createData()
    pin.computeAllTerms(m, d, q, dq)
    out = [q, dq, d.M, d.nle, d.g]
    for frame in (model.frame_E, model.frame_H, model.frame_C):
        o = pin.updateFramePlacement(m, d, frame)
        out += [o.translation, o.rotation]
    out.append(pin.getFrameJacobian(m, d, model.frame_E, pin.LOCAL_WORLD_ALIGNED))
    return [np.array(a, dtype=np.float64) for a in out]


def _unaligned(values: np.ndarray) -> np.ndarray:
    """A float64 array with the values of ``values`` in memory that is not 8-byte aligned."""
    raw = bytearray(values.nbytes + 1)
    a = np.frombuffer(raw, dtype=np.float64, count=values.size, offset=1).reshape(values.shape)
    a[...] = values
    assert not a.flags.aligned
    return a


def _states(n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(3)
    return [(DEFAULT_Q0 + rng.uniform(-0.3, 0.3, 7), rng.uniform(-0.5, 0.5, 7)) for _ in range(n)]


def test_terms_equal_pinocchio_as_c_contiguous_float64(model: RobotModel) -> None:
    for q, dq in _states(5):
        terms = model.terms(q, dq)
        for name, got, want in zip(terms._fields, terms, _reference_terms(model, q, dq), strict=True):
            assert got.dtype == np.float64 and got.flags.c_contiguous and got.flags.aligned, name
            np.testing.assert_array_equal(got, want, err_msg=name)


def test_terms_track_each_call_and_kinematics_are_fresh(model: RobotModel) -> None:
    (q1, dq1), (q2, dq2) = _states(2)
    kin1 = model.kinematics(q1, dq1)
    kept = [a.copy() for a in kin1]
    terms = model.terms(q2, dq2)  # overwrites the model's arrays, not an earlier Kinematics
    for name, a, b in zip(kin1._fields, kin1, kept, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
    np.testing.assert_array_equal(terms.q, q2)
    np.testing.assert_array_equal(terms.p_E, _reference_terms(model, q2, dq2)[5])
    kin2 = model.kinematics(q2, dq2)
    assert not any(np.shares_memory(a, b) for a, b in zip(kin1, kin2, strict=True))


def test_terms_do_not_keep_the_callers_arrays(model: RobotModel) -> None:
    q, dq = _states(1)[0]
    terms = model.terms(q, dq)
    assert not np.shares_memory(terms.q, q) and not np.shares_memory(terms.dq, dq)
    q[:] = 0.0  # the caller's reference moves on; the terms of this tick stay
    assert np.all(terms.q != 0.0)


@pytest.mark.parametrize("bad", [DEFAULT_Q0.reshape(7, 1), DEFAULT_Q0[:6], np.tile(DEFAULT_Q0, (2, 1))],
                         ids=["column", "short", "matrix"])
def test_terms_reject_a_joint_vector_of_the_wrong_shape(model: RobotModel, bad: np.ndarray) -> None:
    """A (7, 1) column used to pass through Pinocchio into the terms, then to a kernel bound to vectors."""
    with pytest.raises(ValueError):
        model.terms(bad, np.zeros(7))
    with pytest.raises(ValueError):
        model.terms(DEFAULT_Q0, bad)


def test_terms_accept_lists_and_other_dtypes(model: RobotModel) -> None:
    q, dq = _states(1)[0]
    want = model.kinematics(q, dq)
    got = model.kinematics(list(q), _unaligned(dq))
    for name, a, b in zip(want._fields, want, got, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)


def test_mass_matrix_inverse_is_the_symmetric_inverse(model: RobotModel) -> None:
    for q, dq in _states(3):
        M = model.kinematics(q, dq).M
        Minv = model.mass_matrix_inverse(q)
        np.testing.assert_array_equal(Minv, Minv.T)
        np.testing.assert_allclose(Minv @ M, np.eye(7), atol=1e-9)
        assert not np.shares_memory(Minv, model.mass_matrix_inverse(q))


def test_scope_axis_at_the_measured_joints(model: RobotModel) -> None:
    (q1, _), (q2, _) = _states(2)
    a1 = model.scope_axis_at(q1)
    kept = [a.copy() for a in a1]
    a2 = model.scope_axis_at(q2)
    for a, b in zip(a1, kept, strict=True):  # fresh arrays: the first axis is not overwritten
        np.testing.assert_array_equal(a, b)
    pose = model.frame_pose(q2, FRAME_E)
    d_z, P = scope_axis(np.ascontiguousarray(pose.rotation))
    np.testing.assert_array_equal(a2.p_E, pose.translation)
    np.testing.assert_array_equal(a2.d_z, d_z)
    np.testing.assert_array_equal(a2.P, P)
    into = model.scope_axis_into(q2)
    for a, b in zip(into, a2, strict=True):
        np.testing.assert_array_equal(a, b)
        assert a.flags.c_contiguous and a.dtype == np.float64


def test_scope_axis_does_not_disturb_the_terms(model: RobotModel) -> None:
    (q1, dq1), (q2, _) = _states(2)
    terms = model.terms(q1, dq1)
    kept = [a.copy() for a in terms]
    model.scope_axis_into(q2)
    model.mass_matrix_inverse(q1)  # the tick's next call, on the same configuration
    for name, a, b in zip(terms._fields, terms, kept, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)


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


def test_valid_readings_pass_on_as_they_are(validator: InputValidator) -> None:
    frame = _frame()
    out = validator.validate(frame)
    assert out.events == []
    assert out.ft is frame.ft and out.tactile is frame.tactile
    assert out.instruments is frame.instruments and out.robot is frame.robot


def _arrays(out: object) -> list[np.ndarray]:
    readings = (out.ft, out.tactile, out.instruments, out.robot)  # type: ignore[attr-defined]
    return [v for r in readings for v in vars(r).values() if isinstance(v, np.ndarray)]


@pytest.mark.parametrize("make", [list, _unaligned, lambda v: np.asarray(v, dtype=np.float32),
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


# -- the controller ------------------------------------------------------------------------------
def test_tick_results_do_not_share_memory_across_ticks() -> None:
    """Every tick's arrays are its own: a consumer may keep a TickResult while the controller runs on."""
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    results = []
    for k in range(3):
        results.append(ctrl.tick(_frame_at(ctrl, k)))
    first = [np.array(a, copy=True) for a in _result_arrays(results[0])]
    for a, b in zip(_result_arrays(results[0]), first, strict=True):
        np.testing.assert_array_equal(a, b)
    for a in _result_arrays(results[0]):
        assert not any(np.shares_memory(a, b) for b in _result_arrays(results[1]))


def _frame_at(ctrl: Controller, k: int) -> SensorFrame:
    assert ctrl.ref is not None
    t = k * ctrl.dt
    return SensorFrame(
        t, ForceTorqueReading(np.array([3.0, 1.0, 0.0]), np.zeros(3), t), TactileReading(np.full(64, 80.0), t),
        InstrumentObservation(np.array([[400.0, 260.0]]), t), RobotReading(ctrl.ref.q, ctrl.ref.dq, None, t),
    )


def _result_arrays(r: object) -> list[np.ndarray]:
    fields = r._asdict()  # type: ignore[attr-defined]
    arrays = [v for v in fields.values() if isinstance(v, np.ndarray)]
    return arrays + list(fields["wrenches"].values())
