"""The supervisor's checks: a command's first broken limit, the nearest joint limit, and the scope
measured at the measured joints."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.rcm.geometry import initial_rcm_point, insertion_depth, rcm_error
from lapwrench.robot.model import RobotModel
from lapwrench.safety.checks import (
    accept_command,
    command_violation,
    measure_scope,
    measured_joints_room,
    measured_step,
    nearest_limit,
    stop_reach,
)
from lapwrench.safety.config import SupervisorConfig
from lapwrench.safety.supervisor import SafetySupervisor
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
STOP_A, STOP_J = 0.9 * A_MAX, 0.9 * J_MAX  # the supervisor's stop: its default stop_fraction


def violation(q: list[float], q_prev: list[float], v_prev: list[float], a_prev: list[float]) -> tuple:
    code, joint, value = command_violation(
        np.array(q), np.array(q_prev), np.array(v_prev), np.array(a_prev), LO, HI, 1e-6, V_MAX, A_MAX, J_MAX,
        STOP_A, STOP_J, DT,
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
    code, joint, value = accept_command(np.array(q), history, LO, HI, 1e-6, V_MAX, A_MAX, J_MAX, STOP_A, STOP_J, DT)
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


# -- a command the stop could not end inside the limits ----------------------------------------------
def test_a_command_whose_stop_would_pass_a_position_limit_is_refused() -> None:
    """1.5 rad/s, 0.1 rad short of the limit: every limit of the command holds, but braking at 9 rad/s^2
    takes 0.125 rad (code 6, where the stop could end). Moving away from the limit is fine."""
    v = 1.5
    code, joint, value = violation([0.0, 0.9], [0.0, 0.9 - v * DT], [0.0, v], [0.0, 0.0])
    assert (code, joint) == (6, 1) and value > 1.0
    assert violation([0.0, 0.9], [0.0, 0.9 + v * DT], [0.0, -v], [0.0, 0.0])[0] == 0
    code, joint, value = violation([-0.9, 0.0], [-0.9 + v * DT, 0.0], [-v, 0.0], [0.0, 0.0])
    assert (code, joint) == (6, 0) and value < -1.0


def test_a_command_whose_stop_would_overspeed_is_refused() -> None:
    """1.99 of 2 rad/s, still accelerating at 9.9 rad/s^2: ramping that out at 4500 rad/s^3 adds 0.011 rad/s."""
    a, v = 9.9, 1.99
    code, joint, value = violation([DT * v, 0.0], [0.0, 0.0], [v - a * DT, 0.0], [a, 0.0])
    assert (code, joint) == (7, 0) and value == pytest.approx(v + a * a / (2 * STOP_J[0]))
    assert violation([DT * v, 0.0], [0.0, 0.0], [v + a * DT, 0.0], [-a, 0.0])[0] == 0  # braking: fine


def test_stop_reach_counts_only_motion_toward_the_direction() -> None:
    assert stop_reach(0.0, 0.0, 9.0, 4500.0, DT) == (0.0, 0.0)  # at rest: nowhere
    assert stop_reach(-1.0, 0.0, 9.0, 4500.0, DT) == (0.0, 0.0)  # moving away, not accelerating back
    speed, travel = stop_reach(1.0, 0.0, 9.0, 4500.0, DT)
    assert speed == 1.0 and travel == pytest.approx(1.0 / 18.0 + 1.0 * 9.0 / 9000.0 + DT)
    speed, _ = stop_reach(-0.1, 9.0, 9.0, 4500.0, DT)  # moving away but accelerating back: its overshoot
    assert speed == pytest.approx(81.0 / 9000.0)


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.lists(st.tuples(st.integers(1, 60), st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7)),
                min_size=1, max_size=4))
def test_stop_reach_bounds_the_supervisors_stop(segments: list[tuple[int, list[float]]]) -> None:
    """Property: from any command state reached at 99 % of the limits (jerk-limited, with room to ramp
    the acceleration out before the velocity limit, as a command must be to be accepted), the
    supervisor's stop travels no farther in either direction, and gets no faster, than
    :func:`stop_reach` says (up to its last cycle's round-off at rest: a reversal of at most j dt^2)."""
    limits = RobotModel("panda").limits
    stop = limits.scaled(SupervisorConfig().stop_fraction)
    s = SafetySupervisor(limits, DT, SupervisorConfig(max_consecutive_misses=0))
    q0 = 0.5 * (limits.position_lower + limits.position_upper)  # far from the limits: nothing refused for them
    s.start(q0)
    shaper = ReferenceShaper(limits, DT, 0.99, 0.0)  # jerk-limited, room to ramp the acceleration out
    ref = ReferenceState(q0.copy(), np.zeros(7), np.zeros(7))
    for n, jerk in segments:
        for _ in range(n):
            ref = shaper.advance(ref, ref.ddq + np.array(jerk) * limits.jerk * DT)
            s.filter(0.0, ref.q)
    q = ref.q
    assert not s.alarm, s.alarm_reason
    q_stop, v_stop, a_stop = s.command_state
    s.stop(0.0)
    path, speeds = [q_stop], [v_stop]
    while not s.at_rest:
        path.append(s.filter(0.0, q))
        speeds.append(s.command_state[1])
    moved, vel = np.array(path) - q_stop, np.array(speeds)
    for j in range(7):
        for sign in (1.0, -1.0):
            peak, travel = stop_reach(sign * v_stop[j], sign * a_stop[j], stop.acceleration[j], stop.jerk[j], DT)
            assert np.max(sign * moved[:, j]) <= travel + 1e-12
            assert np.max(sign * vel[:, j]) <= max(peak, sign * v_stop[j]) + stop.jerk[j] * DT * DT


# -- measured values that are not real numbers --------------------------------------------------------
@pytest.mark.parametrize(
    "bad", [["a"] * 7, DEFAULT_Q0 + 1j, np.array([object()] * 7)], ids=["text", "complex", "objects"]
)
def test_measure_scope_of_joints_that_are_not_real_numbers_is_nan_not_an_exception(bad: object) -> None:
    """The loop measures the scope at the robot's reading before the supervisor sees it: a broken driver's
    reading raised there (text, objects) or was silently cast with a ComplexWarning (complex)."""
    model = RobotModel("panda")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = measure_scope(model, bad, np.zeros(3))
        assert np.isnan(m.rcm_error) and np.isnan(m.depth)
        assert np.isnan(measure_scope(model, DEFAULT_Q0, bad[:3]).rcm_error)


def test_measured_step_is_the_largest_joint_move_and_remembers_the_reading() -> None:
    prev = np.array([0.0, 1.0, -1.0])
    joint, step = measured_step(np.array([0.001, 0.5, -1.0]), prev)
    assert int(joint) == 1 and step == pytest.approx(0.5)
    np.testing.assert_array_equal(prev, [0.001, 0.5, -1.0])
