"""The one control loop: robot state + fresh sensor samples → controller → supervisor → robot.

The same loop drives the virtual model (:class:`lapwrench.virtual.VirtualRobot`), the MuJoCo world
(:class:`lapwrench.sim.robot.SimRobot`) and the Franka (:class:`lapwrench.hardware.franka.FrankaRobot`); what
differs lives behind the :class:`~lapwrench.robot_interface.RobotInterface` and the sources.

One cycle (:meth:`ControlLoop.cycle`)::

    reading = robot.read()                 # on hardware: waits for the robot's next state (1 ms)
    sources polled; frame = SensorFrame(fresh readings, reading)
    result  = controller.tick(frame)       # an exception here is an alarm: the arm stops to rest
    scope   = measure_scope(model, reading.q, result.p_R)
    q       = supervisor.filter(result.q_ref, measured RCM error, depth, ΔF, measured q, busy time)
    robot.command(q)
    after_command(now)                     # the real-time process: F/T drain, shared inputs, peer watch

The hooks (``pre_cycle``, ``after_command``) are guarded like the tick: an exception in one is a ``hook_error``
alarm (the arm stops to rest), never an escape from the loop.

The supervisor watches measured state only (:mod:`lapwrench.safety.supervisor`). A cycle's and a run's records
(:class:`Cycle`, :class:`LoopStats`) live in :mod:`lapwrench.loop_stats`, importable from here.

Time: ``clock()`` gives the loop's time in seconds; the session time ``t`` of a cycle is ``clock() - t0``. On hardware
the clock is ``time.monotonic()`` (the drivers stamp with it) and every cycle's busy time is checked against the
supervisor's budget (deadline misses, and an alarm after too many in a row): its compute time (state read to command
computed) plus the loop's own work around the previous command (the filter, then everything from the command's return
to this read: ``after_command``, ``on_cycle``'s logging, the run's bookkeeping), which all delays the read. In
simulation the clock is the simulated time: the simulated robot waits for the loop, so the compute time is measured
and reported but has no deadline (``wall_deadlines=False``); the time between its cycles is the world's, so only the
filter and the hooks count there.
"""

from __future__ import annotations

import gc
import math
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from lapwrench.controller import Controller, TickResult
from lapwrench.loop_stats import Cycle, Growable, LoopStats
from lapwrench.robot.errors import RobotError
from lapwrench.robot_interface import RobotInterface
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorEvent, SupervisorState, measure_scope
from lapwrench.sensors import RobotReading, SensorFrame
from lapwrench.sources import Source, fresh
from lapwrench.spatial import Vec


class ControlLoop:
    """Runs the controller on a robot at its control rate (module docstring).

    Args:
        robot: A :class:`~lapwrench.robot_interface.RobotInterface`.
        controller: The controller (reset by :meth:`start` at the robot's measured pose).
        supervisor: The safety supervisor every command passes through.
        sources: The controller's inputs (:class:`~lapwrench.sources.Source`), at most one per kind.
        clock: The loop's clock in seconds (default ``time.monotonic``; the simulation passes its time).
        wall_deadlines: Check each cycle's busy time against the supervisor's budget (real robots).
        on_cycle: Called with each :class:`Cycle` after the command was sent (logging, recording).
        on_events: Called with the supervisor's events raised outside a cycle (end of a run,
            robot errors, disconnection).
        command_hook: Test seam for fault injection: ``f(k, q_ref) -> q_ref`` replaces the
            controller's command of cycle ``k`` before the supervisor sees it.
        compute_hook: Test seam: called with ``k`` inside the measured compute time.
        pre_cycle: Called with the clock time right after ``robot.read()``, inside the compute time (the
            real-time process catches up on the F/T socket there after a late cycle).
        after_command: Called with the cycle's clock time right after ``robot.command``, outside the
            compute time: work the command does not wait for, in the slack before the next state (the
            real-time process drains the F/T socket, reads its shared inputs and checks its peers
            there, for the next cycle's tick). Its time counts in the next cycle's busy time.
        before_command: Called with the session time just before ``robot.command`` (the simulation
            applies its scripted forces there).
        stop_timeout: Robot seconds allowed for the final stop to come to rest.
        switch_interval: Python's thread switch interval (s) while :meth:`run` runs; None leaves it.
        gc_freeze: Freeze and disable the cyclic garbage collector for :meth:`run`.
    """

    def __init__(
        self,
        robot: RobotInterface,
        controller: Controller,
        supervisor: SafetySupervisor,
        sources: Sequence[Source] = (),
        *,
        clock: Callable[[], float] = time.monotonic,
        wall_deadlines: bool = True,
        on_cycle: Callable[[Cycle], None] | None = None,
        on_events: Callable[[list[SupervisorEvent]], None] | None = None,
        command_hook: Callable[[int, Vec], Vec] | None = None,
        compute_hook: Callable[[int], None] | None = None,
        pre_cycle: Callable[[float], None] | None = None,
        after_command: Callable[[float], None] | None = None,
        before_command: Callable[[float], None] | None = None,
        stop_timeout: float = 5.0,
        switch_interval: float | None = 1e-4,
        gc_freeze: bool = False,
    ) -> None:
        if switch_interval is not None and not (math.isfinite(switch_interval) and switch_interval > 0):
            raise ValueError(f"switch_interval must be a positive number of seconds, got {switch_interval!r}")
        kinds = [s.kind for s in sources]
        if len(set(kinds)) != len(kinds):
            raise ValueError(f"at most one source per kind, got {kinds}")
        self.robot = robot
        self.controller = controller
        self.supervisor = supervisor
        self.sources = list(sources)
        self.clock = clock
        self.wall_deadlines = wall_deadlines
        self.on_cycle = on_cycle
        self.on_events = on_events
        self.command_hook = command_hook
        self.compute_hook = compute_hook
        self.pre_cycle = pre_cycle
        self.after_command = after_command
        self.before_command = before_command
        self.stop_timeout = stop_timeout
        self.switch_interval = switch_interval
        self.gc_freeze = gc_freeze
        self.t0 = 0.0
        self.k = 0
        self.over_budget = 0
        self._fresh: dict[str, bool] = {}
        self._t_prev: float | None = None
        self._controller_failed = False
        self._hooks_failed: set[str] = set()
        self._tail = 0.0  # the loop's own work around the previous command (s): module docstring
        self._pre_command = 0.0  # the previous cycle's filter time (s)
        self._t_after: float | None = None  # when the previous cycle's command returned (perf_counter)
        self._started = False
        self.last_result: TickResult | None = None
        self.last_reading: RobotReading | None = None

    # -- life cycle ---------------------------------------------------------------------------
    def session_time(self, now: float | None = None) -> float:
        return (self.clock() if now is None else now) - self.t0

    def start(self, p_R: Vec | None = None, tare_q: Vec | None = None) -> RobotReading:
        """Connect the robot, reset the controller at its pose and start supervision. ``tare_q``: where the
        F/T was tared, when not at this pose (a restart; see :meth:`Controller.reset`)."""
        reading = self.robot.connect()
        self.t0 = self.clock()
        for s in self.sources:
            if hasattr(s, "t0"):
                s.t0 = self.t0
        self.controller.reset(reading.q, p_R, tare_q)
        assert self.controller.rcm is not None
        measure_scope(self.controller.model, reading.q, self.controller.rcm.p_R)  # loads its compiled code now
        self.supervisor.start(reading.q, 0.0)
        self._controller_failed = False
        self._hooks_failed.clear()  # a restart's first hook exception is an alarm again
        self._tail, self._t_after = 0.0, None
        self.last_reading = reading
        self._started = True
        self.k = 0
        return reading

    # -- one cycle ----------------------------------------------------------------------------
    def cycle(self) -> Cycle:
        """Read, compute, supervise, command: one control cycle (module docstring)."""
        if not self._started:
            raise RuntimeError("call ControlLoop.start() before cycle()")
        sup = self.supervisor
        t_call = time.perf_counter()
        reading = self.robot.read()
        t_read = time.perf_counter()
        if self.wall_deadlines and self._t_after is not None:  # all since the last command delayed this read
            self._tail = self._pre_command + (t_call - self._t_after)
        now = self.clock()
        if self.pre_cycle is not None:
            self._hook("pre_cycle", self.pre_cycle, now)
        frame = self._frame(now - self.t0, reading)
        result = self._tick(frame)
        if result is not None:
            for ev in result.events:
                sup.counted_event(frame.time, f"input_{ev.source}", ev.message)
            q_ref, p_R, residual = result.q_ref, result.p_R, result.residual
        else:  # the supervisor is stopping on the alarm: it ignores the command
            assert self.controller.rcm is not None or self.last_result is not None
            q_ref, p_R, residual = reading.q, self._p_R(), None
        if self.command_hook is not None:
            q_ref = self.command_hook(self.k, q_ref)
        scope = measure_scope(self.controller.model, reading.q, p_R)
        if self.compute_hook is not None:
            self.compute_hook(self.k)
        compute = time.perf_counter() - t_read
        busy = compute + self._tail
        if busy > sup.cfg.cycle_budget:
            self.over_budget += 1
        q_cmd = sup.filter(
            frame.time,
            q_ref,
            rcm_error=scope.rcm_error,
            depth=scope.depth,
            residual=residual,
            q_measured=reading.q,
            compute_time=busy if self.wall_deadlines else None,
            controller_stopping=result is not None and result.rcm_infeasible,
        )
        if self.before_command is not None:
            self.before_command(frame.time)
        t_command = time.perf_counter()
        self.robot.command(q_cmd)
        t_after = time.perf_counter()
        if self.after_command is not None:
            self._hook("after_command", self.after_command, now)
        self._pre_command, self._t_after = t_command - t_read - compute, t_after
        if not self.wall_deadlines:  # simulated: the time between cycles is the world's; the hooks' alone count
            self._tail = self._pre_command + (time.perf_counter() - t_after)
        period = 0.0 if self._t_prev is None else t_read - self._t_prev
        self._t_prev = t_read
        out = Cycle(self.k, frame, reading, result, scope, q_cmd, compute, period, sup.drain_events())
        if result is not None:
            self.last_result = result
        self.last_reading = reading
        self.k += 1
        if self.on_cycle is not None:
            self.on_cycle(out)
        return out

    def hold_cycle(self) -> Vec:
        """One cycle of the supervisor's stop alone (no controller): read, filter, command. A running supervisor
        is stopped first: its stop goes on from its last command, not the measured pose (a tracking error off)."""
        reading = self.robot.read()
        t = self.session_time()
        if self.supervisor.state is SupervisorState.RUNNING:
            self.supervisor.stop(t, "hold_cycle: held without the controller")
        q_cmd = self.supervisor.filter(t, reading.q, q_measured=reading.q)
        self.robot.command(q_cmd)
        self.flush_events()
        self.last_reading, self._t_after, self._tail = reading, None, 0.0  # the next busy time starts afresh
        self.k += 1
        return q_cmd

    def _hook(self, name: str, hook: Callable[[float], None], now: float) -> None:
        """``hook(now)``; its first exception is a ``hook_error`` alarm (the arm stops to rest), later ones are
        counted events. It is still called every cycle (the real-time process's heartbeat lives there)."""
        try:
            hook(now)
        except Exception as exc:
            message = f"{name}: {type(exc).__name__}: {exc}"
            if name in self._hooks_failed:
                self.supervisor.counted_event(self.session_time(now), "hook_error", message)
            else:
                self._hooks_failed.add(name)
                self.supervisor.raise_alarm(self.session_time(now), "hook_error", message)

    def _p_R(self) -> Vec:
        rcm = self.controller.rcm
        if rcm is not None:
            return rcm.p_R
        assert self.last_result is not None
        return self.last_result.p_R

    def _tick(self, frame: SensorFrame) -> TickResult | None:
        """The controller's tick; an exception becomes a supervisor alarm (None), never a crash. After a
        failed tick the controller is not called again in this run: the supervisor's stop brings the arm to rest."""
        if self._controller_failed:
            return None
        try:
            return self.controller.tick(frame)
        except Exception as exc:
            self._controller_failed = True
            self.supervisor.raise_alarm(frame.time, "controller_error", f"{type(exc).__name__}: {exc}")
            return None

    def _frame(self, t: float, reading: RobotReading) -> SensorFrame:
        """Poll every source and gather the fresh readings: the built-in kinds in their fields, the
        rest (registered inputs) in ``extra`` by name."""
        ft = tactile = instruments = None
        extra: dict[str, Any] = {}
        was_fresh = self._fresh
        for s in self.sources:
            s.poll(t)
            r = fresh(s, t)
            kind = s.kind
            if was_fresh.get(kind) is not (r is not None):  # a change (or the first cycle): note it
                self._note_freshness(t, kind, r is not None)
            if kind == "ft":
                ft = r
            elif kind == "tactile":
                tactile = r
            elif kind == "instruments":
                instruments = r
            else:
                extra[kind] = r
        return SensorFrame(time=t, ft=ft, tactile=tactile, instruments=instruments, robot=reading, extra=extra)

    def _note_freshness(self, t: float, name: str, is_fresh: bool) -> None:
        was = self._fresh.get(name)
        if was is None or was != is_fresh:
            self._fresh[name] = is_fresh
            if not is_fresh:
                self.supervisor.event(t, "input_stale", f"{name}: no sample newer than the max age; its wrench is off")
            elif was is not None:
                self.supervisor.event(t, "input_fresh", f"{name}: fresh again")

    # -- a whole run (hardware) ----------------------------------------------------------------
    def run(
        self, duration: float | None = None, stop_event: threading.Event | None = None, *, disconnect: bool = True
    ) -> LoopStats:
        """Run until ``duration`` robot seconds, ``stop_event``, or a supervisor alarm; then stop cleanly to rest and
        (by default) disconnect.

        pylibfranka's ``readOnce`` keeps the GIL while it blocks, so while sensor threads share the interpreter the
        loop yields it before each ``read`` (a ``time.sleep(0)``, whose timer costs 23 µs p50 on this VM) and shortens
        the switch interval (100 µs by default). The hardware path runs it alone in a process (:mod:`~.hardware.rt`).

        Raises:
            RobotError: the robot failed (the loop disconnects before re-raising).
        """
        previous_interval = sys.getswitchinterval()
        if self.switch_interval is not None:
            sys.setswitchinterval(self.switch_interval)
        gc_was_enabled = gc.isenabled()
        if self.gc_freeze:
            gc.collect()
            gc.freeze()
            gc.disable()
        try:
            return self._run(duration, stop_event, disconnect)
        finally:
            sys.setswitchinterval(previous_interval)
            if self.gc_freeze:
                gc.unfreeze()
                if gc_was_enabled:
                    gc.enable()

    def _run(self, duration: float | None, stop_event: threading.Event | None, disconnect: bool) -> LoopStats:
        if not self._started:
            self.start()
        sup, dt = self.supervisor, self.robot.dt
        n = self.controller.model.nv
        q_start = np.array(self.last_reading.q if self.last_reading else np.zeros(n))
        cyc, comp, rm, rr, cmds = Growable(), Growable(), Growable(), Growable(), Growable(n)
        robot_t = 0.0
        rcm_peak = 0.0  # the measured RCM error's maximum over the whole run (the series keep its end)
        stop_deadline: float | None = None
        wall0 = time.perf_counter()
        try:
            while True:
                if sup.at_rest and stop_deadline is not None:
                    break
                if stop_deadline is None and (
                    (duration is not None and robot_t >= duration - 1e-9)
                    or (stop_event is not None and stop_event.is_set())
                    or sup.state is not SupervisorState.RUNNING  # an identity test: Enum's .value is a slow property
                ):
                    sup.stop(self.session_time(), "end of run" if sup.state is SupervisorState.RUNNING else "alarm")
                    stop_deadline = robot_t + self.stop_timeout
                if stop_deadline is not None and robot_t > stop_deadline:
                    sup.event(self.session_time(), "stop_timeout", "the stop did not reach rest in time")
                    break
                if threading.active_count() > 1:  # let other threads have the GIL before read() holds it
                    time.sleep(0)
                c = self.cycle()
                cyc.append(c.period * 1e6)
                comp.append(c.compute * 1e6)
                e = c.scope.rcm_error
                rm.append(e)
                if e > rcm_peak or e != e:  # a NaN stays the peak (nothing compares greater than it)
                    rcm_peak = e
                rr.append(math.nan if c.result is None else c.result.rcm_error)
                cmds.append(c.q_cmd)
                robot_t += dt
        except RobotError as exc:
            sup.event(self.session_time(), "robot_error", str(exc))
            self.flush_events()
            if disconnect:
                self._safe_disconnect()
            raise
        self.flush_events()
        if disconnect:
            self._safe_disconnect()
        return LoopStats(
            cycles=cyc.n, cycle_us=cyc.array()[1:] if not cyc.dropped else cyc.array(),  # the first has no period
            compute_us=comp.array(), rcm_error_measured=rm.array(), rcm_error_reference=rr.array(),
            commands=cmds.array(), rcm_error_measured_max=rcm_peak if cyc.n else None, q_start=q_start,
            p_R=np.array(self._p_R(), dtype=float), robot_time=robot_t, wall_time=time.perf_counter() - wall0,
            deadline_misses=sup.deadline_misses, over_budget=self.over_budget, alarm=sup.alarm_reason,
            stopped_at_rest=sup.at_rest,
        )

    def flush_events(self) -> None:
        """Hand the supervisor's pending events (raised outside a cycle) to ``on_events``."""
        events = self.supervisor.drain_events()
        if events and self.on_events is not None:
            self.on_events(events)

    def _safe_disconnect(self) -> None:
        try:
            self.robot.disconnect()
        except Exception as exc:  # report, never mask the original outcome
            self.supervisor.event(self.session_time(), "disconnect_error", str(exc))
            self.flush_events()
