"""The supervisor's event log, alarm latch and measured-state watches (:mod:`lapwrench.safety.watches`).

The log and the latch are tested on :class:`SupervisorWatches` itself; the watches run inside
:meth:`SafetySupervisor.filter` (its one subclass), so they are driven through it. The thresholds that
hold the arm are tested in tests/safety/test_supervisor.py; here: what the watches log, how often,
what they remember between cycles, and what a malformed measurement does.
"""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.robot.limits import JointLimits
from lapwrench.robot.model import RobotModel
from lapwrench.safety.config import SupervisorConfig, SupervisorState
from lapwrench.safety.supervisor import SafetySupervisor
from lapwrench.safety.watches import CONTROLLER_STOP_TIMEOUT, SupervisorWatches
from lapwrench.virtual import DEFAULT_Q0

DT = 1e-3
SCOPE_OK = {"rcm_error": 0.001, "depth": 0.058}


@pytest.fixture(scope="module")
def limits() -> JointLimits:
    return RobotModel("panda").limits


def bare(limits: JointLimits, **kw: float) -> SupervisorWatches:
    return SupervisorWatches(SupervisorConfig(**kw), limits.position_lower, limits.position_upper)


def started(limits: JointLimits, **kw: float) -> SafetySupervisor:
    s = SafetySupervisor(limits, DT, SupervisorConfig(**kw))
    s.start(DEFAULT_Q0)
    return s


def kinds(w: SupervisorWatches) -> list[str]:
    return [e.kind for e in w.events]


# -- the event log ----------------------------------------------------------------------------------
def test_a_new_watch_holds_with_nothing_logged(limits: JointLimits) -> None:
    w = bare(limits)
    assert w.state is SupervisorState.HOLDING and not w.alarm and w.alarm_reason is None
    assert list(w.events) == [] and w.pending == [] and w.deadline_misses == 0


def test_an_event_goes_to_the_log_and_to_the_logger_once(limits: JointLimits) -> None:
    w = bare(limits)
    ev = w.event(1, "note", "first")
    assert isinstance(ev.time, float) and ev.time == 1.0
    w.event(2.0, "note", "second")
    assert [e.message for e in w.drain_events()] == ["first", "second"]
    assert w.drain_events() == []  # drained: the logger sees each event once
    assert [e.message for e in w.events] == ["first", "second"]  # the log keeps them


def test_the_log_keeps_the_newest_max_events(limits: JointLimits) -> None:
    w = bare(limits, max_events=3)
    for k in range(5):
        w.event(float(k), "note", str(k))
    assert [e.message for e in w.events] == ["2", "3", "4"]
    assert len(w.drain_events()) == 5  # the logger's queue is not trimmed: it is drained every cycle


def test_a_repeated_event_is_counted_but_logged_first_ten_then_every_thousandth(limits: JointLimits) -> None:
    w = bare(limits)
    for k in range(2500):
        w.counted_event(k * DT, "flood", "again")
    messages = [e.message for e in w.events]
    expected = [f"again (occurrence {n})" for n in [*range(1, 11), 1000, 2000]]
    assert messages == expected
    w.counted_event(9.0, "other", "new kind")  # each kind is counted on its own
    assert w.events[-1].message == "new kind (occurrence 1)"


# -- the alarm latch --------------------------------------------------------------------------------
def test_the_first_alarm_is_kept_and_each_is_logged(limits: JointLimits) -> None:
    s = started(limits)
    s.raise_alarm(0.1, "first", "one")
    s.raise_alarm(0.2, "second", "two")
    assert s.alarm and s.alarm_reason == "first: one"
    assert kinds(s) == ["start", "first", "stop", "second"]  # one stop, when the first alarm came
    assert s.events[2].message == "stopping (first)"
    assert s.state is SupervisorState.STOPPING


def test_an_alarm_while_holding_does_not_start_a_stop(limits: JointLimits) -> None:
    w = bare(limits)  # never started: holding
    w.raise_alarm(0.0, "fault", "while idle")
    assert w.alarm and w.state is SupervisorState.HOLDING and kinds(w) == ["fault"]


def test_a_clean_stop_logs_once_and_raises_no_alarm(limits: JointLimits) -> None:
    s = started(limits)
    s.stop(0.5, "operator")
    s.stop(0.6, "again")
    assert s.state is SupervisorState.STOPPING and not s.alarm
    assert [(e.kind, e.message) for e in s.events][1:] == [("stop", "operator")]
    idle = bare(limits)
    idle.stop(0.0)
    assert idle.state is SupervisorState.HOLDING and list(idle.events) == []


# -- the measured-state watches, through the supervisor's filter -------------------------------------
def test_a_measured_alarm_is_logged_once_while_the_excursion_lasts(limits: JointLimits) -> None:
    s = started(limits)
    for k in range(100):
        s.filter(k * DT, DEFAULT_Q0, rcm_error=0.05, depth=0.5)  # both out of bounds, every cycle
    assert s.alarm_reason.startswith("rcm_error: measured RCM error 50.00 mm")
    assert kinds(s).count("rcm_error") == 1 and "insertion_depth" not in kinds(s)


def test_a_near_joint_limit_is_logged_once_per_approach(limits: JointLimits) -> None:
    s = started(limits, joint_warn_margin=0.05, joint_stop_margin=0.01)
    near, far = DEFAULT_Q0.copy(), DEFAULT_Q0.copy()
    near[2] = limits.position_lower[2] + 0.03
    for q in (near, near, near, far, near):
        s.filter(0.0, DEFAULT_Q0, q_measured=q)
    warnings = [e for e in s.events if e.kind == "joint_limit_near"]
    assert len(warnings) == 2 and not s.alarm  # the second after the joint moved away and back
    assert warnings[0].message == "joint 3 measured 0.0300 rad from its limit"


def test_a_measured_joint_past_its_limit_stops_naming_the_joint(limits: JointLimits) -> None:
    s = started(limits)
    q = DEFAULT_Q0.copy()
    q[6] = limits.position_upper[6] + 0.2  # past the limit: negative room
    s.filter(0.0, DEFAULT_Q0, q_measured=q)
    assert s.alarm and s.alarm_reason == "joint_limit: joint 7 measured -0.2000 rad from its limit"


@pytest.mark.parametrize(
    "q_measured",
    [np.r_[DEFAULT_Q0[:6], np.inf], np.full(7, np.nan), DEFAULT_Q0[:6], np.r_[DEFAULT_Q0, 0.0], np.zeros((7, 1))],
    ids=["inf", "nan", "six", "eight", "column"],
)
def test_malformed_measured_joints_hold(limits: JointLimits, q_measured: np.ndarray) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, q_measured=q_measured)
    assert s.alarm and s.alarm_reason.startswith("joints_nonfinite: measured joints")


def test_measured_joints_of_the_wrong_shape_say_so(limits: JointLimits) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, q_measured=DEFAULT_Q0[:6])
    assert "shape (6,)" in s.alarm_reason and "not finite" not in s.alarm_reason


def test_the_residual_force_timer_restarts_when_the_force_drops(limits: JointLimits) -> None:
    """Two 40 ms pushes over the bound, 10 ms apart, never hold: the time over the bound does not add up."""
    s = started(limits)  # residual_force_time 50 ms, max_residual_force 20 N
    force = [30.0] * 40 + [5.0] * 10 + [30.0] * 40 + [5.0] * 10
    for k, f in enumerate(force):
        s.filter(k * DT, DEFAULT_Q0, residual=np.array([0.0, f, 0.0]), **SCOPE_OK)
    assert not s.alarm


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_a_non_finite_residual_force_holds_at_once(limits: JointLimits, bad: float) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, residual=np.array([0.0, 0.0, bad]), **SCOPE_OK)
    assert s.alarm and s.alarm_reason.startswith("residual_force: measured residual force")
    assert "for 0 ms" in s.alarm_reason


@pytest.mark.parametrize("shape", [(6,), (2,), (3, 1), ()])
def test_a_residual_that_is_not_a_force_holds_saying_so(limits: JointLimits, shape: tuple[int, ...]) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, residual=np.full(shape, 1.0), **SCOPE_OK)  # small values: only the shape is wrong
    assert s.alarm and "residual force has shape" in s.alarm_reason


def test_a_nan_compute_time_is_a_missed_deadline(limits: JointLimits) -> None:
    s = started(limits, cycle_budget=0.0005, max_consecutive_misses=3)
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    s.filter(DT, DEFAULT_Q0, compute_time=0.001)
    s.filter(2 * DT, DEFAULT_Q0, compute_time=float("nan"))  # does not end the run of misses
    assert s.deadline_misses == 3 and s.alarm and "3 consecutive deadline misses" in s.alarm_reason


def test_deadline_misses_are_all_counted_but_rate_limited_in_the_log(limits: JointLimits) -> None:
    s = started(limits, cycle_budget=0.0005, max_consecutive_misses=0)  # 0: misses never stop the arm
    for k in range(1500):
        s.filter(k * DT, DEFAULT_Q0, compute_time=0.001)
    assert s.deadline_misses == 1500 and s.consecutive_misses == 1500 and not s.alarm
    logged = [e.message for e in s.events if e.kind == "deadline_miss"]
    assert len(logged) == 11 and logged[-1] == "cycle busy time 1000 us > 500 us (occurrence 1000)"
    s.filter(2.0, DEFAULT_Q0, compute_time=0.0001)
    assert s.consecutive_misses == 0 and s.deadline_misses == 1500


def _ramp(s: SafetySupervisor, q: np.ndarray, speed: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Pass a shaped reference from rest at ``q`` until every joint moves at ``speed`` (rad/s);
    the reference's position and velocity then."""
    shaper = ReferenceShaper(s.limits, DT, 0.9, 0.05)
    st = ReferenceState(q.copy(), np.zeros(7), np.zeros(7))
    for _ in range(200):
        st = shaper.step(st, np.full(7, speed))
        s.filter(0.0, st.q)
    v = s.command_state[1]
    assert not s.alarm and np.allclose(v, speed, rtol=1e-3)
    return st.q, v


def test_a_controller_that_brakes_but_never_reaches_rest_is_held_after_the_timeout(limits: JointLimits) -> None:
    s = started(limits)
    q, v = _ramp(s, DEFAULT_Q0)
    t0, k = 0.5, 0
    while not s.alarm:
        k += 1
        q = q + DT * v  # the controller says it is braking but keeps its speed
        s.filter(t0 + (k - 1) * DT, q, controller_stopping=True, **SCOPE_OK)
        assert k <= 2000
    assert (k - 1) * DT == pytest.approx(CONTROLLER_STOP_TIMEOUT)
    assert s.alarm_reason.startswith("rcm_infeasible: the RCM task could not be kept")
    assert [e.time for e in s.events if e.kind == "rcm_infeasible"] == [t0, pytest.approx(t0 + CONTROLLER_STOP_TIMEOUT)]


def test_a_controller_at_rest_that_says_it_is_braking_holds_at_once(limits: JointLimits) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, controller_stopping=True)
    assert s.alarm and s.alarm_reason.startswith("rcm_infeasible")
    assert s.at_rest


def test_the_controller_stop_timer_starts_afresh_with_each_run(limits: JointLimits) -> None:
    s = started(limits)
    q, v = _ramp(s, DEFAULT_Q0)
    for k in range(300):  # 0.3 s of a braking controller: under the timeout
        q = q + DT * v
        s.filter(0.5 + k * DT, q, controller_stopping=True)
    assert not s.alarm
    s.start(q, time=5.0)  # a new run, 4.5 s after the first braking began
    q, v = _ramp(s, q)
    s.filter(5.2, q + DT * v, controller_stopping=True)
    assert not s.alarm and s.state is SupervisorState.RUNNING  # a timer left from the first run would hold
