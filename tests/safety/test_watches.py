"""The supervisor's event log, alarm latch and measured-state watches (:mod:`lapwrench.safety.watches`).

The log and the latch are tested on :class:`SupervisorWatches` itself; the watches run inside
:meth:`SafetySupervisor.filter` (its one subclass), so they are driven through it. The thresholds that
hold the arm are tested in tests/safety/test_supervisor.py; here: what the watches log, how often,
what they remember between cycles, and what a malformed measurement does.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.robot.limits import JointLimits
from lapwrench.robot.model import RobotModel
from lapwrench.safety.config import SupervisorConfig, SupervisorState
from lapwrench.safety.supervisor import SafetySupervisor
from lapwrench.safety.watches import CONTROLLER_STOP_TIMEOUT, SupervisorWatches, real_scalar
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


@pytest.mark.parametrize(("watched", "kind"), [
    ({"rcm_error": "0.001"}, "rcm_error"), ({"depth": [0.05, 0.06]}, "insertion_depth"),
    ({"rcm_error": 1e-3 + 0j}, "rcm_error"), ({"depth": True}, "insertion_depth"),
])
def test_a_measured_value_that_is_not_one_real_number_holds(limits: JointLimits, watched: dict, kind: str) -> None:
    """Text raised a TypeError inside the gate; a list, complex or boolean value is no measurement either."""
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, **{**SCOPE_OK, **watched})
    assert s.alarm_reason.startswith(kind)


@pytest.mark.parametrize("busy", ["0.0001", None, [1e-4, 1e-4]])
def test_a_busy_time_that_is_not_one_real_number_is_a_miss(limits: JointLimits, busy: object) -> None:
    s = started(limits)
    s.filter(0.0, DEFAULT_Q0, compute_time=1e-4)
    assert s.deadline_misses == 0
    if busy is None:  # None skips the watch, as documented
        s.filter(DT, DEFAULT_Q0, compute_time=busy)
        assert s.deadline_misses == 0
        return
    s.filter(DT, DEFAULT_Q0, compute_time=busy)  # type: ignore[arg-type]
    assert s.deadline_misses == 1 and not s.alarm


def test_real_scalar_takes_one_real_number_only() -> None:
    assert real_scalar(0.5) == 0.5 and real_scalar(2) == 2.0 and real_scalar(np.float32(0.25)) == 0.25
    assert real_scalar(np.array([3.0])) == 3.0
    for bad in ("1", b"1", True, 1j, [1.0, 2.0], None, object(), np.zeros(0)):
        assert math.isnan(real_scalar(bad)), bad


def test_a_near_joint_limit_is_logged_once_per_approach(limits: JointLimits) -> None:
    s = started(limits, joint_warn_margin=0.05, joint_stop_margin=0.01)
    near, far = DEFAULT_Q0.copy(), DEFAULT_Q0.copy()
    near[2] = limits.position_lower[2] + 0.035
    far[2] = limits.position_lower[2] + 0.052  # out of the warning band, a plausible step (< max_joint_step) away
    for q in (near, near, near, far, near):
        s.filter(0.0, DEFAULT_Q0, q_measured=q)
    warnings = [e for e in s.events if e.kind == "joint_limit_near"]
    assert len(warnings) == 2 and not s.alarm  # the second after the joint moved away and back
    assert warnings[0].message == "joint 3 measured 0.0350 rad from its limit"


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


# -- timed watches do not trust the caller's clock ---------------------------------------------------
CLOCKS = {
    "frozen": lambda k: 1.0,
    "backwards": lambda k: 10.0 - k * DT,
    "nan": lambda k: float("nan"),
}


@pytest.mark.parametrize("clock", sorted(CLOCKS))
def test_a_residual_force_that_stays_holds_after_its_time_whatever_the_clock(limits: JointLimits, clock: str) -> None:
    """The time over the bound counted the session time alone: a stale, backward or NaN clock never held
    a 30 N load on the wall. The cycles count too now (one filter call per control period)."""
    s = started(limits)
    for k in range(51):
        assert not s.alarm
        s.filter(CLOCKS[clock](k), DEFAULT_Q0, residual=np.array([30.0, 0.0, 0.0]), **SCOPE_OK)
    assert s.alarm and s.alarm_reason.startswith("residual_force") and "for 50 ms" in s.alarm_reason


@pytest.mark.parametrize("clock", sorted(CLOCKS))
def test_a_braking_controller_is_held_after_the_timeout_whatever_the_clock(limits: JointLimits, clock: str) -> None:
    s = started(limits)
    q, v = _ramp(s, DEFAULT_Q0)
    k = 0
    while not s.alarm:
        q = q + DT * v  # says it is braking, keeps its speed
        s.filter(CLOCKS[clock](k), q, controller_stopping=True, **SCOPE_OK)
        k += 1
        assert k <= 2000
    assert k - 1 == round(CONTROLLER_STOP_TIMEOUT / DT) and s.alarm_reason.startswith("rcm_infeasible")


# -- a measured joint that jumps -----------------------------------------------------------------------
def test_a_measured_joint_that_jumps_holds_even_where_the_scope_watches_cannot_see_it(limits: JointLimits) -> None:
    """A 1 rad glitch of the last joint turns the scope about its own axis: the RCM error and the depth do
    not change, and before, nothing held. No arm moves 1 rad in a millisecond: a corrupt reading holds."""
    s = started(limits)
    q, v = _ramp(s, DEFAULT_Q0, speed=0.05)
    measured = q.copy()
    for k in range(20):  # readings that follow the arm: no alarm
        q, measured = q + DT * v, measured + DT * v
        s.filter(0.5 + k * DT, q, q_measured=measured, **SCOPE_OK)
    assert not s.alarm
    glitch = measured + np.eye(7)[6]
    s.filter(0.52, q + DT * v, q_measured=glitch, **SCOPE_OK)  # the scope watches are content
    assert s.alarm and s.alarm_reason.startswith("joints_jump: measured joint 7 moved 1.0000 rad in one cycle")
    assert s.state is SupervisorState.STOPPING  # the smooth stop, not a halt


def test_readings_at_full_speed_across_a_gap_or_a_restart_do_not_count_as_jumps(limits: JointLimits) -> None:
    s = started(limits)
    q = DEFAULT_Q0.copy()
    for k in range(5):  # 2.6 rad/s with two cycles lost between readings: 5 mrad a reading
        q = q + 2 * DT * limits.velocity
        s.filter(k * DT, DEFAULT_Q0, q_measured=q)
    s.filter(0.1, DEFAULT_Q0)  # a cycle without a reading: the next one is not compared with the last
    s.filter(0.2, DEFAULT_Q0, q_measured=q + 0.1)
    s.start(DEFAULT_Q0, time=0.3)  # a restart: the first reading is compared with nothing
    s.filter(0.3, DEFAULT_Q0, q_measured=DEFAULT_Q0 + 0.1)
    assert not s.alarm and "joints_jump" not in kinds(s)


def test_a_late_reading_may_have_moved_for_every_cycle_since_but_a_glitch_still_holds(limits: JointLimits) -> None:
    """A cycle that comes 10 ms late (by the session clock) reads the arm 10 cycles further: at the Franka's
    fastest joint speed, 26 mrad, more than one cycle's ``max_joint_step``; a 1 rad glitch still holds."""
    s = started(limits)
    q, t = DEFAULT_Q0.copy(), 0.0
    for _ in range(3):
        t += 10 * DT
        q = q + 10 * DT * limits.velocity.max()
        s.filter(t, DEFAULT_Q0, q_measured=q)
    assert not s.alarm and "joints_jump" not in kinds(s)
    s.filter(t + 10 * DT, DEFAULT_Q0, q_measured=q + np.eye(7)[6])
    assert s.alarm and s.alarm_reason.startswith("joints_jump: measured joint 7 moved 1.0000 rad in 10 cycles")


def test_a_measured_joint_past_its_limit_during_a_stop_without_an_alarm_raises_one(limits: JointLimits) -> None:
    """During a stop asked for (end of run, Ctrl-C), a joint measured past its limit was not reported at all:
    the run ended as a clean stop. The measured-state watches alarm there; so does the joint-limit watch now."""
    s = started(limits)
    q, _ = _ramp(s, DEFAULT_Q0)
    s.stop(0.5, "end of run")
    past = DEFAULT_Q0.copy()
    past[0] = limits.position_upper[0] + 0.1
    s.filter(0.501, q, q_measured=past)
    assert s.alarm and s.alarm_reason == "joint_limit: joint 1 measured -0.1000 rad from its limit"
    assert kinds(s)[-2:] == ["stop", "joint_limit"]  # no second stop: the one under way goes on


def test_deadline_misses_during_the_stop_raise_one_alarm_not_one_per_cycle(limits: JointLimits) -> None:
    """Each miss past the bound raised another ``deadline`` alarm event: one per millisecond for as long as
    the misses went on (1149 in 1.15 s), which pushed the cause out of the bounded log and the ring."""
    s = started(limits, cycle_budget=0.0005, max_consecutive_misses=3)
    q, v = _ramp(s, DEFAULT_Q0)
    for k in range(1500):
        s.filter(0.5 + k * DT, q + (k + 1) * DT * v, compute_time=0.001)  # the reference keeps its speed
    assert s.alarm and s.alarm_reason.startswith("deadline: 3 consecutive deadline misses")
    assert kinds(s).count("deadline") == 1 and s.deadline_misses == 1500 and s.at_rest


# -- measured values that are not real numbers -------------------------------------------------------
@pytest.mark.parametrize(
    ("measured", "reason"),
    [
        ({"q_measured": ["a"] * 7}, "joints_nonfinite: measured joints ['a'"),
        ({"q_measured": DEFAULT_Q0 + 1j}, "joints_nonfinite: measured joints array("),
        ({"q_measured": np.array([object()] * 7)}, "joints_nonfinite: measured joints array("),
        ({"residual": ["x", "y", "z"]}, "residual_force: measured residual force ['x'"),
        ({"residual": np.array([1j, 0.0, 0.0])}, "residual_force: measured residual force array("),
    ],
    ids=["joints-text", "joints-complex", "joints-objects", "residual-text", "residual-complex"],
)
def test_measured_values_that_are_not_real_numbers_hold_without_an_exception(
    limits: JointLimits, measured: dict, reason: str
) -> None:
    """Text or objects raised out of the filter (the loop's cycle); complex values were cast to their real
    part with a ComplexWarning (an exception where warnings are errors). A broken driver's reading holds."""
    s = started(limits)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = s.filter(0.0, DEFAULT_Q0, **measured)
    assert np.array_equal(out, DEFAULT_Q0) and s.alarm and s.alarm_reason.startswith(reason), s.alarm_reason


def test_a_huge_finite_residual_force_is_measured_without_an_overflow(limits: JointLimits) -> None:
    """|ΔF| of (1e200, 1e200, 0) overflowed in the dot product (a RuntimeWarning, an exception where warnings
    are errors); it is 1.4e200 N, over the bound, and holds after its time like any other."""
    s = started(limits)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(51):
            s.filter(k * DT, DEFAULT_Q0, residual=np.array([1e200, 1e200, 0.0]), **SCOPE_OK)
    assert s.alarm and s.alarm_reason.startswith("residual_force: measured residual force |ΔF| 1414213562373095")
