"""SafetySupervisor on its own: command checks as libfranka differentiates, watches, clean stop."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lapwrench.config import load
from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.robot.limits import JointLimits, limit_usage
from lapwrench.robot.model import RobotModel
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig, SupervisorState
from lapwrench.virtual import DEFAULT_Q0

DT = 1e-3


@pytest.fixture(scope="module")
def limits() -> JointLimits:
    return RobotModel("panda").limits


def started(limits: JointLimits, **kw: Any) -> SafetySupervisor:
    s = SafetySupervisor(limits, DT, SupervisorConfig(**kw))
    s.start(DEFAULT_Q0)
    return s


def run_to_rest(s: SafetySupervisor, q: np.ndarray, cmds: list[np.ndarray], limit: int = 5000) -> None:
    n = 0
    while not s.at_rest:
        cmds.append(s.filter(0.0, q))
        n += 1
        assert n < limit
    for _ in range(3):
        cmds.append(s.filter(0.0, q))


def test_valid_commands_pass_unchanged(limits: JointLimits) -> None:
    s = started(limits)
    q = DEFAULT_Q0.copy()
    for k in range(50):
        q = q + 1e-6 * k * np.ones(7)  # gentle ramp
        out = s.filter(k * DT, q)
        assert np.array_equal(out, q)
    assert s.state is SupervisorState.RUNNING and not s.alarm


def test_every_form_of_a_command_is_checked_and_remembered_alike(limits: JointLimits) -> None:
    """float64 arrays take a compiled path of their own: lists and strided views give the same commands
    and the same history, and the command handed back is the caller's own copy."""
    fast, slow, strided = started(limits), started(limits), started(limits)
    q = DEFAULT_Q0.copy()
    for k in range(40):
        q = q + 2e-7 * k * np.arange(1, 8)
        out = fast.filter(k * DT, q)
        assert np.array_equal(out, slow.filter(k * DT, list(q)))
        assert np.array_equal(out, strided.filter(k * DT, np.repeat(q, 2)[::2]))
        out += 1.0  # the caller's copy: the supervisor's history does not move with it
    for a, b, c in zip(fast.command_state, slow.command_state, strided.command_state, strict=True):
        assert np.array_equal(a, b) and np.array_equal(a, c)
    assert np.array_equal(fast.command_state[0], q) and not fast.alarm


@pytest.mark.parametrize(
    ("bad", "kind"),
    [
        (np.full(7, np.nan), "command_nonfinite"),
        (np.r_[np.inf, np.zeros(6)], "command_nonfinite"),
        (np.zeros(6), "command_invalid"),
        ("junk", "command_invalid"),
        (DEFAULT_Q0 + np.r_[10.0, 0, 0, 0, 0, 0, 0], "command_position"),
        (DEFAULT_Q0 + np.r_[0.01, 0, 0, 0, 0, 0, 0], "command_velocity"),  # 10 rad/s
        (DEFAULT_Q0 + np.r_[1e-4, 0, 0, 0, 0, 0, 0], "command_acceleration"),  # 100 rad/s^2 from rest
        (DEFAULT_Q0 + np.r_[1e-5, 0, 0, 0, 0, 0, 0], "command_jerk"),  # 10000 rad/s^3 > 7500
    ],
)
def test_bad_command_is_replaced_by_a_stop(limits: JointLimits, bad: np.ndarray | str, kind: str) -> None:
    s = started(limits)
    out = s.filter(0.1, bad)
    assert np.all(np.isfinite(out)) and np.allclose(out, DEFAULT_Q0)
    assert s.alarm and s.alarm_reason.startswith(kind), s.alarm_reason
    assert any(e.kind == kind for e in s.events)
    assert s.replaced_commands == 1


def test_jerk_exactly_at_the_limit_passes(limits: JointLimits) -> None:
    s = started(limits)
    step = limits.jerk * DT**3  # q = j dt^3 from rest: v = j dt^2, a = j dt, jerk = j exactly
    assert s.check_command(DEFAULT_Q0 + step * 0.999) is None
    assert s.check_command(DEFAULT_Q0 + step * 1.01)[0] == "command_jerk"


def test_rcm_error_over_bound_holds_with_alarm(limits: JointLimits) -> None:
    s = started(limits, max_rcm_error=0.005)
    out = s.filter(0.0, DEFAULT_Q0, rcm_error=0.004)
    assert not s.alarm
    s.filter(0.001, DEFAULT_Q0, rcm_error=0.006)
    assert s.alarm and "rcm_error" in s.alarm_reason
    assert s.at_rest  # from rest, the stop is immediate
    assert np.allclose(s.filter(0.002, DEFAULT_Q0 + 0.1), out)  # further commands are ignored
    s2 = started(limits)
    s2.filter(0.0, DEFAULT_Q0, rcm_error=float("nan"))
    assert s2.alarm


def test_measured_joint_near_limit(limits: JointLimits) -> None:
    s = started(limits, joint_warn_margin=0.05, joint_stop_margin=0.01)
    near = DEFAULT_Q0.copy()
    near[0] = limits.position_upper[0] - 0.03
    s.filter(0.0, DEFAULT_Q0, q_measured=near)
    assert not s.alarm and any(e.kind == "joint_limit_near" for e in s.events)
    near[0] = limits.position_upper[0] - 0.005
    s.filter(0.001, DEFAULT_Q0, q_measured=near)
    assert s.alarm and "joint_limit" in s.alarm_reason


def test_deadline_misses_counted_and_consecutive_ones_stop(limits: JointLimits) -> None:
    s = started(limits, cycle_budget=0.0005, max_consecutive_misses=3)
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    s.filter(0.0, DEFAULT_Q0, compute_time=0.0001)  # resets the run of misses
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    assert s.deadline_misses == 3 and not s.alarm
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    s.filter(0.0, DEFAULT_Q0, compute_time=0.001)
    assert s.alarm and s.alarm_reason.startswith("deadline")


@pytest.mark.parametrize("kind", ["panda", "fr3"])
def test_clean_stop_reaches_rest_inside_the_limits(kind: str) -> None:
    """From random moving states (full-speed shaped references), the stop ends at rest within limits."""
    lim = RobotModel(kind).limits
    rng = np.random.default_rng(3)
    for _ in range(60):
        s = SafetySupervisor(lim, DT, SupervisorConfig(max_consecutive_misses=0))
        s.start(DEFAULT_Q0)
        shaper = ReferenceShaper(lim, DT, 0.9, 0.05)
        st = ReferenceState(DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7))
        target = rng.uniform(-1, 1, 7) * lim.velocity
        cmds = []
        for _k in range(int(rng.integers(1, 600))):
            st = shaper.step(st, target)
            cmds.append(s.filter(0.0, st.q))
        assert not s.alarm
        s.stop(0.0)
        run_to_rest(s, st.q, cmds)
        usage = limit_usage(np.array(cmds), DT, lim, DEFAULT_Q0)
        assert usage["velocity"] <= 1 and usage["acceleration"] <= 1 and usage["jerk"] <= 1, usage
        assert np.allclose(cmds[-1], cmds[-2]) and np.allclose(cmds[-2], cmds[-3])
        _q, v, a = s.command_state
        assert np.allclose(v, 0) and np.allclose(a, 0)


def test_filter_before_start_is_an_error(limits: JointLimits) -> None:
    with pytest.raises(RuntimeError):
        SafetySupervisor(limits, DT).filter(0.0, DEFAULT_Q0)


def test_config_validation() -> None:
    with pytest.raises(ValueError):
        SupervisorConfig(check_fraction=1.5)
    with pytest.raises(ValueError):
        SupervisorConfig(joint_stop_margin=0.1, joint_warn_margin=0.05)


# -- measured-state watches (issue 9): each one holds with an alarm naming the quantity and value --
def moving(
    limits: JointLimits, seed: int = 5, ticks: int = 300
) -> tuple[SafetySupervisor, np.ndarray, list[np.ndarray]]:
    """A supervisor (from the shipped config) passing a shaped full-speed reference: the arm is moving."""
    s = SafetySupervisor(limits, DT, SupervisorConfig.from_config(load(), max_consecutive_misses=0))
    s.start(DEFAULT_Q0)
    shaper = ReferenceShaper(limits, DT, 0.9, 0.05)
    st = ReferenceState(DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7))
    target = np.random.default_rng(seed).uniform(-1, 1, 7) * limits.velocity
    cmds = []
    for _ in range(ticks):
        st = shaper.step(st, target)
        cmds.append(s.filter(0.0, st.q, rcm_error=0.001, depth=0.058, residual=np.array([1.0, 2.0, 0.0])))
    assert not s.alarm and np.max(np.abs(s.command_state[1])) > 0.1
    return s, st.q, cmds


def assert_stopped_at_rest_inside_limits(
    s: SafetySupervisor, q: np.ndarray, cmds: list[np.ndarray], limits: JointLimits
) -> None:
    run_to_rest(s, q + 0.3, cmds)  # commands after the hold are ignored, however far they jump
    usage = limit_usage(np.array(cmds), DT, limits, DEFAULT_Q0)
    assert usage["position_excess"] == 0 and max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1, usage
    assert np.allclose(cmds[-1], cmds[-2]) and np.allclose(cmds[-2], cmds[-3])
    _q, v, a = s.command_state
    assert np.allclose(v, 0) and np.allclose(a, 0)


HOLDS = {
    "rcm_error": ({"rcm_error": 0.0062}, "rcm_error: measured RCM error 6.20 mm > 5.00 mm; holding"),
    "depth_below": ({"depth": 0.020}, "insertion_depth: measured insertion depth 20.0 mm outside [25.0, 125.0] mm"),
    "depth_above": ({"depth": 0.131}, "insertion_depth: measured insertion depth 131.0 mm outside [25.0, 125.0] mm"),
    "residual": (
        {"residual": np.array([12.0, -16.0, 15.0])},
        "residual_force: measured residual force |ΔF| 25.0 N > 20.0 N",
    ),
    "rcm_nan": ({"rcm_error": np.nan}, "rcm_error: measured RCM error nan mm"),
    "rcm_inf": ({"rcm_error": np.inf}, "rcm_error: measured RCM error inf mm"),
    "depth_nan": ({"depth": np.nan}, "insertion_depth: measured insertion depth nan mm"),
    "residual_nan": ({"residual": np.array([np.nan, 0.0, 0.0])}, "residual_force: measured residual force |ΔF| nan N"),
    "joints_nan": ({"q_measured": np.r_[DEFAULT_Q0[:3], np.nan, DEFAULT_Q0[4:]]}, "joints_nonfinite: measured joints"),
}


@pytest.mark.parametrize("case", sorted(HOLDS))
def test_measured_state_holds_with_an_alarm_naming_it(limits: JointLimits, case: str) -> None:
    measured, reason = HOLDS[case]
    s, q, cmds = moving(limits)
    kw = {"rcm_error": 0.001, "depth": 0.058, "residual": np.zeros(3), **measured}
    # a finite residual force must persist for residual_force_time (50 ms) before it holds
    ticks = 51 if case == "residual" else 1
    if ticks > 1:
        v = s.command_state[1]
        for k in range(1, ticks):  # the reference keeps its speed meanwhile
            cmds.append(s.filter(0.3 + (k - 1) * DT, q + k * DT * v, **kw))
            assert not s.alarm
        q = q + ticks * DT * v
    cmds.append(s.filter(0.3 + (ticks - 1) * DT, q, **kw))
    assert s.alarm and s.alarm_reason.startswith(reason), s.alarm_reason
    assert s.state is SupervisorState.STOPPING  # a jerk-limited stop, not a jump to a halt
    assert s.replaced_commands == 0
    assert_stopped_at_rest_inside_limits(s, q, cmds, limits)


def test_a_residual_force_transient_shorter_than_its_time_does_not_hold(limits: JointLimits) -> None:
    """A hand letting go of 30 N at once: |ΔF| ~26 N for ~25 ms while the force estimate catches up."""
    s = started(limits)
    for k in range(40):
        f = 26.0 if k < 25 else 2.0
        s.filter(k * DT, DEFAULT_Q0, rcm_error=0.001, depth=0.058, residual=np.array([f, 0.0, 0.0]))
    assert not s.alarm
    for k in range(40, 120):  # then a load that stays: held after 50 ms
        s.filter(k * DT, DEFAULT_Q0, rcm_error=0.001, depth=0.058, residual=np.array([26.0, 0.0, 0.0]))
    assert s.alarm and "residual_force" in s.alarm_reason and "for 50 ms" in s.alarm_reason


@pytest.mark.parametrize(
    "measured",
    [
        {"rcm_error": 0.005, "depth": 0.025, "residual": np.array([20.0, 0.0, 0.0])},  # on the bounds
        {"rcm_error": 0.0, "depth": 0.125, "residual": None},  # no ΔF (a sensor missing): skipped
        {"rcm_error": None, "depth": None, "residual": None},
    ],
)
def test_measured_state_inside_the_bounds_passes(limits: JointLimits, measured: dict) -> None:
    s = started(limits)
    assert np.array_equal(s.filter(0.0, DEFAULT_Q0, q_measured=DEFAULT_Q0, **measured), DEFAULT_Q0)
    assert not s.alarm


def test_measured_bounds_come_from_the_yaml_config() -> None:
    cfg = load().replace(safety={"max_rcm_error": 0.003, "depth_tolerance": 0.002, "max_residual_force": 8.0})
    cfg = cfg.replace(envelope={"depth_min": 0.04, "depth_max": 0.1})
    c = SupervisorConfig.from_config(cfg, cycle_budget=0.002)
    assert (c.max_rcm_error, c.max_residual_force, c.cycle_budget) == (0.003, 8.0, 0.002)
    assert c.depth_min == pytest.approx(0.038) and c.depth_max == pytest.approx(0.102)
    assert SupervisorConfig() == SupervisorConfig.from_config(load())  # the defaults are the shipped YAML's
    assert SupervisorConfig.from_config(cfg, max_rcm_error=0.01).max_rcm_error == 0.01
    with pytest.raises(ValueError):
        SupervisorConfig(depth_min=0.1, depth_max=0.05)
    with pytest.raises(ValueError):
        SupervisorConfig(max_residual_force=float("nan"))


def test_a_braking_controller_is_followed_to_rest_then_held_with_an_alarm(limits: JointLimits) -> None:
    """TickResult.rcm_infeasible: the controller's own braking commands pass (they keep the RCM as far
    as the limits allow); once they are at rest the arm holds with an alarm."""
    s, q, cmds = moving(limits)
    v = s.command_state[1]
    # a reference braking uniformly from its speed to rest over 0.5 s
    for k in range(1, 511):
        q = q + DT * v * max(0.0, 1.0 - k / 500.0)
        cmds.append(s.filter(0.3 + k * DT, q, rcm_error=0.001, depth=0.058, controller_stopping=True))
        if s.alarm:
            break
        assert s.state is SupervisorState.RUNNING and np.array_equal(cmds[-1], q)  # passed unchanged
    assert s.alarm and s.alarm_reason.startswith("rcm_infeasible")
    assert any(e.kind == "rcm_infeasible" and "braking" in e.message for e in s.events)
    assert_stopped_at_rest_inside_limits(s, q, cmds, limits)


# -- every command accepted is one the stop can end inside the limits ---------------------------------
def sent_inside_the_limits(cmds: list[np.ndarray], limits: JointLimits, q_start: np.ndarray) -> None:
    """The stream the robot received, differentiated from rest at ``q_start`` as libfranka does, breaks
    no position (beyond the supervisor's tolerance), velocity, acceleration or jerk limit."""
    q = np.array(cmds)
    assert np.all(q <= limits.position_upper + 1e-6) and np.all(q >= limits.position_lower - 1e-6), (
        np.max(q - limits.position_upper), np.max(limits.position_lower - q)
    )
    usage = limit_usage(q, DT, limits, q_start)
    assert max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1.0 + 1e-9, usage


def hostile_step(q: np.ndarray, v: np.ndarray, a: np.ndarray, a_want: np.ndarray, limits: JointLimits,
                 fraction: float = 0.9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One command of a controller inside ``fraction`` of the velocity/acceleration/jerk limits that knows
    nothing of the position limits: acceleration ``a_want`` reached at the jerk limit."""
    lim = limits.scaled(fraction)
    a = np.clip(np.clip(a_want, -lim.acceleration, lim.acceleration), a - lim.jerk * DT, a + lim.jerk * DT)
    v_new = np.clip(v + a * DT, -lim.velocity, lim.velocity)
    a = (v_new - v) / DT
    return q + v_new * DT, v_new, a


@pytest.mark.parametrize("direction", [1.0, -1.0])
@pytest.mark.parametrize("joint", range(7))
def test_a_controller_running_into_a_joint_limit_is_stopped_before_it(
    limits: JointLimits, joint: int, direction: float
) -> None:
    """A reference at 90 % of the speed limit heading for a joint limit without braking: every command is
    inside the limits until the last, but a stop begun there needs ~0.15 rad. The supervisor refuses the
    first command it could not stop from, so its stop ends inside the position limit (before: 0.15 rad past)."""
    s = started(limits)
    q, v, a = DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7)
    cmds: list[np.ndarray] = []
    for _ in range(5000):
        q, v, a = hostile_step(q, v, a, 50.0 * (direction * 0.9 * limits.velocity * np.eye(7)[joint] - v), limits)
        cmds.append(s.filter(0.0, q))
        if s.alarm:
            break
    assert s.alarm and s.alarm_reason.startswith("command_stop_position"), s.alarm_reason
    run_to_rest(s, q, cmds)
    sent_inside_the_limits(cmds, limits, DEFAULT_Q0)


@pytest.mark.parametrize("joint", range(7))
def test_full_acceleration_up_to_full_speed_is_refused_before_its_stop_could_overspeed(
    limits: JointLimits, joint: int
) -> None:
    """Accelerating at the acceleration limit right up to the velocity limit: each command is inside both,
    but a stop from the last must first ramp the acceleration out, and the speed grows meanwhile (up to
    a²/2j, +0.8 % on joint 1 before). The supervisor refuses the command its stop could not keep under
    the velocity limit."""
    s = started(limits)
    q, v, a = DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7)
    push = np.eye(7)[joint] * limits.acceleration
    cmds: list[np.ndarray] = []
    for _ in range(2000):
        q, v, a = hostile_step(q, v, a, push, limits, fraction=0.9995)
        cmds.append(s.filter(0.0, q))
        if s.alarm:
            break
    assert s.alarm and s.alarm_reason.startswith("command_stop_velocity"), s.alarm_reason
    run_to_rest(s, q, cmds)
    sent_inside_the_limits(cmds, limits, DEFAULT_Q0)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(
    start=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7),
    segments=st.lists(
        st.tuples(st.integers(1, 150), st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7)), min_size=1, max_size=8
    ),
    fault=st.sampled_from(["stop", "alarm", "measured_rcm"]),
)
def test_any_stream_of_commands_and_any_stop_reach_the_robot_inside_every_limit(
    start: list[float], segments: list[tuple[int, list[float]]], fault: str
) -> None:
    """Property: from any start pose inside the limits, a controller at the hard velocity/acceleration
    limits with random jerks and no care for the position limits, then a stop (asked, alarm, or a measured
    fault), the commands the robot receives break no limit and end at rest."""
    limits = RobotModel("panda").limits
    q0 = limits.position_lower + np.array(start) * (limits.position_upper - limits.position_lower)
    s = SafetySupervisor(limits, DT, SupervisorConfig(max_consecutive_misses=0))
    s.start(q0)
    q, v, a = q0.copy(), np.zeros(7), np.zeros(7)
    cmds: list[np.ndarray] = []
    for n, jerk in segments:
        for _ in range(n):
            q, v, a = hostile_step(q, v, a, a + np.array(jerk) * limits.jerk * DT, limits, fraction=1.0)
            cmds.append(s.filter(0.0, q))
    if fault == "stop":
        s.stop(0.0)
    elif fault == "alarm":
        s.raise_alarm(0.0, "test", "a fault")
    cmds.append(s.filter(0.0, q, rcm_error=1.0 if fault == "measured_rcm" else None))
    run_to_rest(s, q, cmds)
    sent_inside_the_limits(cmds, limits, q0)
    _q, v_end, a_end = s.command_state
    assert np.all(v_end == 0) and np.all(a_end == 0)


# -- a resume after a hold ---------------------------------------------------------------------------
def held_after_an_alarm(limits: JointLimits) -> tuple[SafetySupervisor, list[np.ndarray]]:
    """A moving arm held by a measured RCM alarm: the supervisor at rest, its commands so far."""
    s, q, cmds = moving(limits)
    cmds.append(s.filter(0.3, q, rcm_error=0.05))
    run_to_rest(s, q, cmds)
    return s, cmds


def test_a_resume_after_a_hold_does_not_jump(limits: JointLimits) -> None:
    """The robot holds the last command; the controller restarts at the *measured* pose, a tracking error
    away (0.3 mrad here). Before, the supervisor restarted from the measured pose too and the robot's
    reference jumped by the tracking error in one cycle (300 rad/s^2). Now the offset is phased out."""
    s, cmds = held_after_an_alarm(limits)
    held = cmds[-1]
    measured = held + 3e-4 * np.array([1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
    s.start(measured, time=1.0)
    assert not s.alarm and s.state is SupervisorState.RUNNING and s.resume_cycles > 0
    shaper = ReferenceShaper(limits, DT, 0.9, 0.05)
    st_ref = ReferenceState(measured.copy(), np.zeros(7), np.zeros(7))
    out, refs = [], []
    for k in range(s.resume_cycles + 200):
        st_ref = shaper.step(st_ref, np.full(7, 0.3))
        refs.append(st_ref.q)
        out.append(s.filter(1.0 + k * DT, st_ref.q))
        assert not s.alarm, s.alarm_reason
    assert np.array_equal(out[-1], st_ref.q)  # once phased out, the controller's commands pass unchanged
    sent_inside_the_limits(cmds + out, limits, DEFAULT_Q0)
    # the first command continues from the held one, by the controller's own first step
    assert np.allclose(out[0] - held, refs[0] - measured, rtol=0, atol=1e-7)


def test_a_start_far_from_the_held_reference_starts_afresh(limits: JointLimits) -> None:
    """An offset no tracking error explains (the arm was moved): no phase-out, an event says so."""
    s, cmds = held_after_an_alarm(limits)
    far = cmds[-1] + 0.05
    s.start(far, time=1.0)
    assert s.resume_cycles == 0 and any(e.kind == "start_afresh" for e in s.events)
    assert np.array_equal(s.filter(1.0, far), far)


def test_a_supervisor_with_new_thresholds_continues_the_held_stream(limits: JointLimits) -> None:
    """A parameter change (the UI's) builds a supervisor with new thresholds. A fresh one started from the
    measured pose while the robot held the old one's last command (9x the jerk limit through the UI);
    :meth:`continue_from` hands the held reference over, so the next start resumes from it."""
    old, cmds = held_after_an_alarm(limits)
    new = SafetySupervisor(limits, DT, SupervisorConfig(max_rcm_error=0.02))
    new.continue_from(old)
    measured = cmds[-1] + 2e-4
    new.start(measured, time=1.0)
    assert new.resume_cycles > 0 and not new.alarm
    out = [new.filter(1.0 + k * DT, measured) for k in range(new.resume_cycles + 5)]
    sent_inside_the_limits(cmds + out, limits, DEFAULT_Q0)
    assert np.array_equal(out[-1], measured)


def test_only_a_supervisor_at_rest_of_the_same_robot_is_handed_over(limits: JointLimits) -> None:
    running = started(limits)
    with pytest.raises(ValueError, match="at rest"):
        SafetySupervisor(limits, DT).continue_from(running)
    with pytest.raises(ValueError, match="at rest"):
        SafetySupervisor(limits, DT).continue_from(SafetySupervisor(limits, DT))  # never started
    held, _ = held_after_an_alarm(limits)
    for other in (limits.scaled(0.5), RobotModel("fr3").limits):
        with pytest.raises(ValueError, match="another robot"):
            SafetySupervisor(other, DT).continue_from(held)
    with pytest.raises(ValueError, match="another robot"):
        SafetySupervisor(limits, 2 * DT).continue_from(held)


@pytest.mark.parametrize("bad", [DEFAULT_Q0 + 0j, ["a"] * 7, np.array([object()] * 7)])
def test_a_command_that_is_not_real_numbers_is_refused_without_a_warning(limits: JointLimits, bad: object) -> None:
    """A complex command was cast to its real part with a ComplexWarning (an exception where warnings are
    errors), text raised; both are a refused command now."""
    s = started(limits)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = s.filter(0.0, bad)
    assert np.array_equal(out, DEFAULT_Q0) and s.alarm_reason.startswith("command_invalid")
