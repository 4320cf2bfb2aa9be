"""The supervisor's checks: a command's first broken limit, the nearest joint limit, and the scope
measured at the measured joints."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.rcm.geometry import initial_rcm_point, insertion_depth, rcm_error
from lapwrench.robot.model import RobotModel
from lapwrench.safety.checks import (
    accept_command,
    command_violation,
    measure_scope,
    measured_joints_room,
    nearest_limit,
)
from lapwrench.virtual import DEFAULT_Q0


def test_measure_scope_at_the_measured_joints() -> None:
    """Distance from p_R to the axis and tip depth beyond p_R, against the tick's kinematics."""
    model = RobotModel("panda")
    L = model.length
    rng = np.random.default_rng(9)
    for _ in range(20):
        q = DEFAULT_Q0 + rng.uniform(-0.3, 0.3, 7)
        kin = model.kinematics(q, np.zeros(7))
        lateral = np.cross(kin.d_z, rng.normal(size=3))
        lateral *= 0.006 / np.linalg.norm(lateral)
        p_R = kin.p_E + 0.7 * L * kin.d_z + lateral
        m = measure_scope(model, q, p_R)
        assert m.rcm_error == pytest.approx(0.006, abs=1e-12)
        assert m.depth == pytest.approx(0.3 * L, abs=1e-12)
    bad = measure_scope(model, np.full(7, np.nan), np.zeros(3))
    assert np.isnan(bad.rcm_error) and np.isnan(bad.depth)
    assert np.isnan(measure_scope(model, DEFAULT_Q0, np.array([np.nan, 0.0, 0.0])).rcm_error)
    assert np.isnan(measure_scope(model, np.zeros(6), np.zeros(3)).depth)


def test_measured_scope_is_the_ticks_geometry_at_the_measured_joints() -> None:
    """The supervisor's measured RCM error and depth (its own forward kinematics pass) equal eq (27)'s
    |e_R| and the depth of :mod:`lapwrench.rcm.geometry` on the tick's kinematics at the same joints."""
    model = RobotModel("panda")
    L = model.length
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = DEFAULT_Q0 + rng.uniform(-0.3, 0.3, 7)
        kin = model.kinematics(q, rng.normal(size=7))
        p_R = initial_rcm_point(kin, L, 0.8) + rng.normal(scale=0.005, size=3)
        m = measure_scope(model, q, p_R)
        assert m.rcm_error == pytest.approx(np.linalg.norm(rcm_error(kin, p_R)), abs=1e-12)
        assert m.depth == pytest.approx(insertion_depth(kin, p_R, L), abs=1e-12)


DT = 1e-3
LO, HI = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
V_MAX, A_MAX, J_MAX = np.array([2.0, 2.0]), np.array([10.0, 10.0]), np.array([5000.0, 5000.0])


def violation(q: list[float], q_prev: list[float], v_prev: list[float], a_prev: list[float]) -> tuple:
    code, joint, value = command_violation(
        np.array(q), np.array(q_prev), np.array(v_prev), np.array(a_prev), LO, HI, 1e-6, V_MAX, A_MAX, J_MAX, DT
    )
    return int(code), int(joint), float(value)


def test_a_command_at_rest_inside_the_limits_breaks_nothing() -> None:
    assert violation([0.5, -0.5], [0.5, -0.5], [0.0, 0.0], [0.0, 0.0]) == (0, 0, 0.0)


def test_the_position_limit_is_checked_first_with_its_tolerance() -> None:
    assert violation([0.0, 1.0 + 1e-7], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0])[0] == 0  # inside the tolerance
    code, joint, value = violation([0.0, 1.1], [0.0, 1.1], [0.0, 0.0], [0.0, 0.0])
    assert (code, joint) == (1, 1) and value == pytest.approx(1.1)


def test_velocity_acceleration_and_jerk_as_libfranka_differentiates_them() -> None:
    # v = 3 rad/s on joint 1, reached smoothly (a = 0, jerk = 0): a velocity violation
    code, joint, value = violation([0.0, 3.0 * DT], [0.0, 0.0], [0.0, 3.0], [0.0, 0.0])
    assert (code, joint) == (2, 1) and value == pytest.approx(3.0)
    # v = 1 rad/s after 1 - 11 dt: a = 11 rad/s^2 (held, jerk = 0), an acceleration violation on joint 0
    code, joint, value = violation([DT, 0.0], [0.0, 0.0], [1.0 - 11.0 * DT, 0.0], [11.0, 0.0])
    assert (code, joint) == (3, 0) and value == pytest.approx(11.0)
    # a = 5 rad/s^2 after 5 - 6: jerk 6000 rad/s^3 over its 5000
    code, joint, value = violation([DT, 0.0], [0.0, 0.0], [1.0 - 5.0 * DT, 0.0], [-1.0, 0.0])
    assert (code, joint) == (4, 0) and value == pytest.approx(6000.0)


def test_the_worst_joint_is_named() -> None:
    code, joint, value = violation([2.5 * DT, -3.0 * DT], [0.0, 0.0], [2.5, -3.0], [0.0, 0.0])
    assert (code, joint) == (2, 1) and value == pytest.approx(-3.0)


def test_nearest_limit_is_the_joint_with_the_least_room() -> None:
    joint, room = nearest_limit(np.array([0.0, 0.9, -0.2]), np.full(3, -1.0), np.full(3, 1.0))
    assert int(joint) == 1 and room == pytest.approx(0.1)
    joint, room = nearest_limit(np.array([-0.95, 0.9, -0.2]), np.full(3, -1.0), np.full(3, 1.0))
    assert int(joint) == 0 and room == pytest.approx(0.05)


def _accept(q: list[float], history: np.ndarray) -> tuple:
    code, joint, value = accept_command(np.array(q), history, LO, HI, 1e-6, V_MAX, A_MAX, J_MAX, DT)
    return int(code), int(joint), float(value)


def test_an_accepted_command_becomes_the_history_as_libfranka_differentiates_it() -> None:
    history = np.array([[0.1, -0.2], [0.5, 0.0], [2.0, 0.0]])  # q, v, a of the last command
    q = [0.1 + 0.5 * DT + 1e-7, -0.2]
    assert _accept(q, history) == (0, 0, 0.0)
    v = (np.array(q) - [0.1, -0.2]) / DT
    a = (v - [0.5, 0.0]) / DT
    np.testing.assert_array_equal(history, [q, v, a])  # bit for bit numpy's backward differences


def test_a_rejected_command_leaves_the_history_and_says_what_command_violation_says() -> None:
    cases = [([0.0, 1.1], [0.0, 1.1]), ([0.0, 3.0 * DT], [0.0, 0.0])]  # position; velocity
    for q, q_prev in cases:
        history = np.array([q_prev, [0.0, 3.0 if q[1] < 0.5 else 0.0], [0.0, 0.0]])
        before = history.copy()
        got = _accept(q, history)
        assert got[0] in (1, 2) and got == violation(q, list(history[0]), list(history[1]), list(history[2]))
        np.testing.assert_array_equal(history, before)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_command_is_refused_and_named(bad: float) -> None:
    history = np.zeros((3, 2))
    code, joint, _ = _accept([0.0, bad], history)
    assert (code, joint) == (5, 1)
    assert not history.any()


def test_measured_joints_room_is_nearest_limit_for_finite_joints_only() -> None:
    lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    q = np.array([0.0, 0.9, -0.2])
    finite, joint, room = measured_joints_room(q, lo, hi)
    assert finite and (joint, room) == nearest_limit(q, lo, hi)
    finite, _, _ = measured_joints_room(np.array([0.0, np.nan, 0.0]), lo, hi)
    assert not finite
