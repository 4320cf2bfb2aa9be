"""The robot model: the end-effector Jacobian against finite differences, and the terms handed to the
compiled tick (Pinocchio's results in its own layouts, tracking each call, shapes checked)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from helpers import kinematics_at_rest, numeric_jacobian, random_configuration, unaligned

from lapwrench.robot.description import FRAME_E
from lapwrench.robot.model import RobotModel, inverse_inertia, scope_axis
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
    fk = m.createData()  # {E}'s acceleration at zero joint acceleration, from a kinematics pass of its own
    pin.forwardKinematics(m, fk, q, dq, np.zeros(m.nv))
    out.append(pin.getFrameClassicalAcceleration(m, fk, model.frame_E, pin.LOCAL_WORLD_ALIGNED).vector)
    return [np.array(a, dtype=np.float64) for a in out]


def _states(n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(3)
    return [(DEFAULT_Q0 + rng.uniform(-0.3, 0.3, 7), rng.uniform(-0.5, 0.5, 7)) for _ in range(n)]


@pytest.mark.parametrize("seed", range(5))
def test_end_effector_jacobian(any_model: RobotModel, seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_configuration(any_model, rng)
    kin = kinematics_at_rest(any_model, q)
    J_v = numeric_jacobian(lambda x: kinematics_at_rest(any_model, x).p_E, q)
    R0 = kin.R_E
    J_w = numeric_jacobian(lambda x: R0 @ pin.log3(R0.T @ kinematics_at_rest(any_model, x).R_E), q)
    np.testing.assert_allclose(kin.J_E[3:], J_v, atol=1e-6)
    np.testing.assert_allclose(kin.J_E[:3], J_w, atol=1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_the_acceleration_at_rest_joints_is_the_time_derivative_of_the_twist(any_model: RobotModel, seed: int) -> None:
    """a_E = J̇_E θ̇ (θ̈ = 0): the twist J_E(q + t θ̇) θ̇ differentiated in t by central differences."""
    rng = np.random.default_rng(seed)
    q, dq = random_configuration(any_model, rng), rng.uniform(-1.0, 1.0, any_model.nv)
    h = 1e-6
    twist = [any_model.kinematics(q + s * h * dq, dq).twist_E for s in (1.0, -1.0)]
    np.testing.assert_allclose(any_model.kinematics(q, dq).a_E, (twist[0] - twist[1]) / (2 * h), atol=1e-6)


def test_terms_equal_pinocchio_in_the_layouts_the_tick_is_bound_to(model: RobotModel) -> None:
    """Pinocchio's own arrays: float64, aligned, its matrices column-major, everything else C-contiguous
    (the compiled tick is bound to exactly these types: a change would make it misread them)."""
    column_major = {"M_upper", "R_E", "R_H", "R_C"}
    for q, dq in _states(5):
        terms = model.terms(q, dq)
        for name, got, want in zip(terms._fields, terms, _reference_terms(model, q, dq), strict=True):
            assert got.dtype == np.float64 and got.flags.aligned, name
            assert got.flags.f_contiguous if name in column_major else got.flags.c_contiguous, name
            np.testing.assert_array_equal(got, want, err_msg=name)


def test_kinematics_hold_c_contiguous_copies(model: RobotModel) -> None:
    q, dq = _states(1)[0]
    kin = model.kinematics(q, dq)
    for name, a in zip(kin._fields, kin, strict=True):
        assert a.dtype == np.float64 and a.flags.c_contiguous, name
    np.testing.assert_array_equal(kin.M, kin.M.T)


def test_the_ticks_inverse_inertia_is_pinocchios(model: RobotModel) -> None:
    for q, dq in _states(3):
        M = model.kinematics(q, dq).M
        np.testing.assert_allclose(inverse_inertia(M), model.mass_matrix_inverse(q), rtol=1e-10,
                                   atol=1e-12 * np.abs(M).max())
    assert np.isnan(inverse_inertia(np.diag([1.0, 0.0, 1.0]))).all()  # not positive definite: no number


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
    got = model.kinematics(list(q), unaligned(dq))
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
