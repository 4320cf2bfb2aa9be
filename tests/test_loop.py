"""The one control loop (lapwrench.loop) on the virtual robot: sources, supervisor, deadlines, faults."""

from __future__ import annotations

import time

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.hardware.runner import ControlLoop as HardwareLoop
from lapwrench.inputs import Reading
from lapwrench.loop import ControlLoop
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig
from lapwrench.sensors import ForceTorqueReading, TactileReading
from lapwrench.sources import Observable
from lapwrench.virtual import DEFAULT_Q0, VirtualRobot, tactile_for_delta

CFG = load()
DT = CFG.robot.dt


def _loop(budget: float = 0.0008, **kw: object) -> tuple[ControlLoop, list[float]]:
    clock = [0.0]
    robot = VirtualRobot("panda", DEFAULT_Q0, DT)
    ctrl = Controller(CFG)
    sup = SafetySupervisor(ctrl.model.limits, DT,
                           SupervisorConfig.from_config(CFG, max_consecutive_misses=3, cycle_budget=budget))
    sources = [
        Observable("ft", lambda t: ForceTorqueReading(np.array([10.0, 0.0, 0.0]), np.zeros(3), t),
                   update_interval=DT, max_age=0.005),
        Observable("tactile", lambda t: TactileReading(tactile_for_delta(2.0, CFG.interaction.k_H), t),
                   update_interval=DT, max_age=0.005),
    ]
    loop = ControlLoop(robot, ctrl, sup, sources, clock=lambda: clock[0], switch_interval=None, **kw)  # type: ignore[arg-type]
    loop.start()
    return loop, clock


def _cycles(loop: ControlLoop, clock: list[float], n: int) -> list:  # type: ignore[type-arg]
    out = []
    for _ in range(n):
        out.append(loop.cycle())
        clock[0] += DT
    return out


def test_the_hand_moves_the_virtual_robot_through_the_loop() -> None:
    loop, clock = _loop(wall_deadlines=False)
    cycles = _cycles(loop, clock, 500)
    assert all(c.result is not None and c.result.mode == "handle" for c in cycles[1:])
    assert np.linalg.norm(loop.robot.q - DEFAULT_Q0) > 1e-3  # type: ignore[attr-defined]
    assert max(c.scope.rcm_error for c in cycles) < 1e-3
    assert all(c.compute > 0.0 for c in cycles)


def test_a_silent_source_is_reported_stale_and_its_wrench_is_off() -> None:
    loop, clock = _loop(wall_deadlines=False)
    ft = loop.sources[0]
    _cycles(loop, clock, 10)
    ft.read = lambda t: None  # type: ignore[attr-defined]  # the F/T goes silent
    cycles = _cycles(loop, clock, 20)
    kinds = [e.kind for c in cycles for e in c.events]
    assert "input_stale" in kinds
    assert cycles[-1].frame.ft is None and not cycles[-1].result.wrenches["interaction"].any()


def test_wall_clock_deadlines_only_when_asked() -> None:
    slow = lambda k: time.sleep(0.002)  # noqa: E731  # 2 ms of compute, over the 0.8 ms budget
    loop, clock = _loop(wall_deadlines=False, compute_hook=slow)
    _cycles(loop, clock, 5)
    assert loop.supervisor.deadline_misses == 0 and loop.over_budget == 5 and not loop.supervisor.alarm
    loop, clock = _loop(wall_deadlines=True, compute_hook=slow)
    _cycles(loop, clock, 5)
    assert loop.supervisor.deadline_misses == 5 and loop.supervisor.alarm  # 3 in a row: alarm


def test_after_command_runs_once_a_cycle_after_the_command_and_counts_in_the_next_busy_time() -> None:
    """The real-time process's F/T drain, shared inputs and peer watch: after ``robot.command``, with the
    cycle's clock time; not compute time, but the next cycle's busy time, which the deadline is checked on
    (the hook delays the next state read as much as the compute does)."""
    order: list[tuple[str, float]] = []

    def after(now: float) -> None:
        order.append(("after", now))
        time.sleep(0.06)  # over a 50 ms budget, which no tick's compute comes near even on a busy machine

    loop, clock = _loop(budget=0.05, wall_deadlines=True, after_command=after)
    command = loop.robot.command
    loop.robot.command = lambda q: (order.append(("command", clock[0])), command(q))[1]  # type: ignore[method-assign]
    cycles = _cycles(loop, clock, 4)
    assert [kind for kind, _ in order] == ["command", "after"] * 4
    assert [now for kind, now in order if kind == "after"] == pytest.approx([k * DT for k in range(4)])
    assert all(c.compute < 0.05 for c in cycles)  # the 60 ms slept after each command is not compute time
    # ... but cycles 2-4 start 60 ms late: three misses in a row, the deadline alarm
    assert loop.supervisor.deadline_misses == 3 and loop.over_budget == 3
    assert (loop.supervisor.alarm_reason or "").startswith("deadline")


def test_on_hardware_all_work_between_a_command_and_the_next_read_counts_in_the_busy_time() -> None:
    """``on_cycle`` (the run log) and the caller's own work between cycles delay the next state read as
    much as the hooks do: both count in the next cycle's busy time when the deadlines are the wall clock's
    (before, only the hooks did, and 60 ms of logging a cycle went unseen)."""
    # a budget of 0.2 s, which no cycle's own work comes near even on a machine loaded to 4x its cores
    loop, clock = _loop(budget=0.2, wall_deadlines=True, on_cycle=lambda c: time.sleep(0.25))
    _cycles(loop, clock, 4)
    assert loop.supervisor.deadline_misses == 3 and (loop.supervisor.alarm_reason or "").startswith("deadline")
    loop, clock = _loop(budget=0.2, wall_deadlines=True)
    for _ in range(3):
        loop.cycle()
        time.sleep(0.25)  # the caller between two cycles
    assert loop.supervisor.deadline_misses == 2 and loop.over_budget == 2


def test_in_simulation_the_time_between_cycles_is_the_worlds_not_the_loops() -> None:
    """Without wall-clock deadlines (the simulated robot waits for the loop), what happens between cycles
    (the world stepping, rendering, recording traces) is not the loop's busy time; its hooks still are."""
    loop, clock = _loop(budget=0.05, wall_deadlines=False, on_cycle=lambda c: time.sleep(0.06))
    _cycles(loop, clock, 3)
    assert loop.over_budget == 0
    loop, clock = _loop(budget=0.05, wall_deadlines=False, after_command=lambda now: time.sleep(0.06))
    _cycles(loop, clock, 3)
    assert loop.over_budget == 2 and loop.supervisor.deadline_misses == 0


def test_a_hold_cycle_starts_the_next_busy_time_afresh() -> None:
    loop, _ = _loop(budget=0.05, wall_deadlines=True)
    loop.cycle()
    time.sleep(0.06)
    loop.hold_cycle()  # outside the controller's cycles: the next cycle's busy time is measured from here
    loop.cycle()
    assert loop.supervisor.deadline_misses == 0
    # nor does it carry the last cycle's busy time over: one slow hook is one miss, not two
    slow = [0.06]
    loop, _ = _loop(budget=0.05, wall_deadlines=True, after_command=lambda now: time.sleep(slow.pop() if slow else 0))
    loop.cycle()
    loop.cycle()  # its busy time holds the 60 ms hook after the first command
    loop.hold_cycle()
    loop.cycle()
    assert loop.supervisor.deadline_misses == 1


def test_a_quick_after_command_hook_is_no_deadline_miss() -> None:
    loop, clock = _loop(budget=0.05, wall_deadlines=True, after_command=lambda now: None)
    _cycles(loop, clock, 50)
    assert loop.supervisor.deadline_misses == 0 and not loop.supervisor.alarm


@pytest.mark.parametrize("hook", ["pre_cycle", "after_command"])
def test_a_hook_exception_is_an_alarm_and_the_arm_stops_at_rest(hook: str) -> None:
    """A hook (the real-time process's F/T drain, peer watch, ...) that raises mid-run: an alarm naming it and
    the stop to rest, not an exception out of the loop with the arm moving. The hook is still called."""
    calls: list[float] = []

    def flaky(now: float) -> None:
        calls.append(now)
        if len(calls) >= 300:
            raise OSError("boom")

    loop, clock = _loop(wall_deadlines=False, **{hook: flaky})
    cycles = _cycles(loop, clock, 299)
    assert not loop.supervisor.alarm and cycles[-1].result is not None
    for _ in range(5000):
        if loop.supervisor.at_rest:
            break
        loop.cycle()
        clock[0] += DT
    assert (loop.supervisor.alarm_reason or "").startswith(f"hook_error: {hook}: OSError: boom")
    assert loop.supervisor.at_rest and len(calls) > 301  # still called while stopping


def test_after_a_restart_a_hook_exception_is_an_alarm_again() -> None:
    """The loop forgets a failed hook when it starts again, as it forgets a failed controller."""
    failing = [True]

    def hook(now: float) -> None:
        if failing[0]:
            raise OSError("boom")

    loop, clock = _loop(wall_deadlines=False, after_command=hook)
    _cycles(loop, clock, 1)
    assert (loop.supervisor.alarm_reason or "").startswith("hook_error")
    failing[0] = False
    loop.start()
    _cycles(loop, clock, 5)
    assert not loop.supervisor.alarm
    failing[0] = True
    _cycles(loop, clock, 1)
    assert (loop.supervisor.alarm_reason or "").startswith("hook_error: after_command")


def test_a_controller_exception_becomes_an_alarm_and_the_arm_stops_at_rest() -> None:
    loop, clock = _loop(wall_deadlines=False)
    _cycles(loop, clock, 200)
    loop.controller.tick = lambda frame: 1 / 0  # type: ignore[method-assign, assignment, misc]
    c = loop.cycle()
    assert c.result is None and loop.supervisor.alarm
    assert loop.supervisor.alarm_reason.startswith("controller_error")  # type: ignore[union-attr]
    for _ in range(5000):
        if loop.supervisor.at_rest:
            break
        loop.hold_cycle()
    assert loop.supervisor.at_rest


def test_one_loop_class_serves_virtual_simulated_and_hardware_runs() -> None:
    from lapwrench.sim.loop import ClosedLoop

    assert issubclass(HardwareLoop, ControlLoop)
    assert ClosedLoop.__init__.__code__.co_names.count("ControlLoop") == 1


def test_two_sources_of_one_kind_are_refused() -> None:
    ctrl = Controller(CFG)
    sup = SafetySupervisor(ctrl.model.limits, DT)
    ft = Observable("ft", lambda t: None, update_interval=DT, max_age=0.01)
    with pytest.raises(ValueError, match="one source per kind"):
        ControlLoop(VirtualRobot("panda", DEFAULT_Q0, DT), ctrl, sup, [ft, ft])


def test_registered_inputs_reach_the_frame_and_each_freshness_change_is_one_event() -> None:
    loop, clock = _loop(wall_deadlines=False)
    alive = [True]
    probe = Observable("probe", lambda t: Reading(np.array([t]), t) if alive[0] else None, update_interval=DT,
                       max_age=0.003)
    loop.sources.append(probe)
    first = _cycles(loop, clock, 5)
    assert all(c.frame.extra["probe"].value[0] == c.frame.time for c in first)
    alive[0] = False
    silent = _cycles(loop, clock, 10)
    alive[0] = True
    back = _cycles(loop, clock, 5)
    assert silent[-1].frame.extra["probe"] is None and back[-1].frame.extra["probe"] is not None
    kinds = [e.kind for c in first + silent + back for e in c.events if e.kind in ("input_stale", "input_fresh")]
    assert kinds == ["input_stale", "input_fresh"]  # once each, not every cycle
    assert back[-1].frame.ft is not None and back[-1].frame.tactile is not None


@pytest.mark.parametrize("threads", [1, 2])
def test_a_run_yields_the_gil_before_each_read_only_while_other_threads_share_the_interpreter(
    threads: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The yield (``time.sleep(0)``) lets a sensor thread run while ``readOnce`` holds the GIL; alone in its
    process (the real-time child) the loop has no one to yield to, and the sleep's timer costs each cycle
    23 µs p50 on a VM: it is left out."""
    import threading

    import lapwrench.loop

    sleeps: list[float] = []
    monkeypatch.setattr(lapwrench.loop.time, "sleep", sleeps.append)
    monkeypatch.setattr(threading, "active_count", lambda: threads)
    loop, _ = _loop(wall_deadlines=False)
    st = loop.run(0.05)
    assert st.cycles >= 50 and loop.supervisor.at_rest
    assert sleeps == ([] if threads == 1 else [0] * st.cycles)


def test_a_hold_cycle_while_running_stops_from_the_last_command_not_the_measured_pose() -> None:
    """The measured joints lag the commands by a tracking error: holding from them would send that error as one
    step. The supervisor's stop continues the command stream instead, within the acceleration limit, no alarm."""
    loop, clock = _loop(wall_deadlines=False)
    sent: list[np.ndarray] = []
    command = loop.robot.command
    loop.robot.command = lambda q: (sent.append(np.array(q)), command(q))[1]  # type: ignore[method-assign]
    _cycles(loop, clock, 300)  # the hand moves the arm
    read = loop.robot.read
    lag = np.full(7, 2e-3)  # rad: a tracking error
    loop.robot.read = lambda: (lambda r: type(r)(r.q - lag, r.dq, r.external_force, r.stamp))(read())  # type: ignore[method-assign]
    for _ in range(5):
        loop.hold_cycle()
        clock[0] += DT
    assert not loop.supervisor.alarm
    assert any(e.kind == "stop" and "hold_cycle" in e.message for e in loop.supervisor.events)
    q = np.array(sent[-8:])
    acc = np.diff(q, 2, axis=0) / DT**2
    assert np.all(np.abs(acc) <= loop.supervisor.limits.acceleration + 1e-6)
    assert np.max(np.abs(q[-1] - q[-6])) < 1e-3  # no jump towards the measured pose
