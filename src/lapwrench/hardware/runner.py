"""The 1 kHz control loop: robot state + fresh sensor samples → controller → supervisor → robot.

Threads: every sensor source (F/T, tactile, camera, the instrument detector) runs its own thread
and publishes into a :class:`~lapwrench.drivers.buffer.LatestValue`. The loop only *peeks*: each
cycle it takes the newest sample of each buffer if it is at most ``max_age`` old
(:meth:`~lapwrench.drivers.buffer.LatestValue.get_fresh`), otherwise ``None`` — and a ``None``
input switches that source's wrench off in the controller. Nothing in the loop waits on a sensor,
a camera, a detector or the log file (the :class:`~lapwrench.hardware.log.RunLogger` writes from
its own thread).

One cycle::

    reading = robot.read()                # blocks until the robot's next state (1 ms)
    frame   = SensorFrame(fresh samples, reading)
    result  = controller.tick(frame)      # an exception here is an alarm: the arm stops to rest
    scope   = measure_scope(model, reading.q, result.p_R)
    q       = supervisor.filter(result.q_ref, measured RCM error, depth, ΔF, measured q, compute time)
    robot.command(q)
    logger.cycle(...)

The supervisor watches measured state only (:mod:`lapwrench.hardware.supervisor`), the same as
the simulated loop :class:`~lapwrench.sim.loop.ClosedLoop` does.

Clocks: ``frame.time`` and sample stamps are session seconds on ``time.monotonic()`` (the clock
the drivers stamp with); the robot's own time is logged beside it. The loop works unchanged with
:class:`~lapwrench.hardware.franka.FrankaRobot` and :class:`~lapwrench.sim.robot.SimRobot`.
"""

from __future__ import annotations

import gc
import math
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from lapwrench.controller import Controller, TickResult
from lapwrench.drivers.buffer import LatestValue
from lapwrench.hardware.log import CycleRecord, RunLogger
from lapwrench.hardware.supervisor import SafetySupervisor, measure_scope
from lapwrench.robot.interface import RobotError, RobotInterface
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.spatial import Vec


@dataclass(frozen=True)
class SourceAges:
    """Maximum sample age (s) per source; older samples count as absent (wrench off)."""

    ft: float = 0.02
    tactile: float = 0.1
    instruments: float = 0.2

    def __post_init__(self) -> None:
        for name in ("ft", "tactile", "instruments"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"max age of {name} must be positive, got {v!r}")


@dataclass
class Sources:
    """The latest-value buffers the loop reads.

    ``ft`` holds objects with ``force``/``torque`` (N, N m, handle frame {H}), e.g.
    :class:`~lapwrench.drivers.ft.Wrench`; ``tactile`` objects with ``values`` (64 elements), e.g.
    :class:`~lapwrench.drivers.tactile.TactileFrame`; ``instruments``
    :class:`~lapwrench.sensors.InstrumentObservation` (its ``stamp`` is ignored: the sample's
    timestamp is used). ``None``: no such source.
    """

    ft: LatestValue[Any] | None = None
    tactile: LatestValue[Any] | None = None
    instruments: LatestValue[InstrumentObservation] | None = None


class DetectorWorker:
    """Runs an instrument detector on the newest camera frame in its own thread.

    Publishes :class:`~lapwrench.sensors.InstrumentObservation` (image points of every detection)
    into :attr:`buffer`, timestamped with the *camera frame's* time, so the loop's age check covers
    capture + detection latency.

    Args:
        frames: The camera's buffer (values with an ``image`` RGB array).
        detector: Anything with ``detect(image) -> list`` of objects with ``u``/``v``.
        poll_s: Sleep when no new frame is there.
    """

    def __init__(self, frames: LatestValue[Any], detector: Any, poll_s: float = 0.002) -> None:
        self.frames = frames
        self.detector = detector
        self.poll_s = poll_s
        self.buffer: LatestValue[InstrumentObservation] = LatestValue("instruments")
        self.errors = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lapwrench-detector", daemon=True)

    def start(self) -> DetectorWorker:
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self) -> None:
        last = 0
        while not self._stop.is_set():
            s = self.frames.get()
            if s is None or s.seq == last:
                self._stop.wait(self.poll_s)
                continue
            last = s.seq
            try:
                dets = self.detector.detect(s.value.image)
                pts = np.array([[d.u, d.v] for d in dets], dtype=float).reshape(-1, 2)
            except Exception:  # a failing detection leaves the data stale, never kills the thread
                self.errors += 1
                continue
            self.buffer.put(InstrumentObservation(pts, s.timestamp), s.timestamp)


@dataclass
class LoopStats:
    """What a run measured. Times in microseconds; ``cycle_us`` is the period between reads."""

    cycles: int = 0
    cycle_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    compute_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_measured: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_reference: np.ndarray = field(default_factory=lambda: np.zeros(0))
    commands: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    q_start: np.ndarray = field(default_factory=lambda: np.zeros(7))
    p_R: np.ndarray = field(default_factory=lambda: np.zeros(3))
    robot_time: float = 0.0
    wall_time: float = 0.0
    deadline_misses: int = 0
    alarm: str | None = None
    stopped_at_rest: bool = False

    def percentile(self, what: Literal["cycle", "compute"], p: float) -> float:
        a = self.cycle_us if what == "cycle" else self.compute_us
        return float(np.percentile(a, p)) if a.size else float("nan")

    def summary(self) -> dict[str, float | int | str | bool | None]:
        """The run's figures with units in the key names (for the CLI and the loop benchmark)."""
        return {
            "robot_time_s": round(self.robot_time, 3),
            "wall_time_s": round(self.wall_time, 3),
            "cycles": self.cycles,
            "cycle_p50_us": round(self.percentile("cycle", 50), 1),
            "cycle_p99_us": round(self.percentile("cycle", 99), 1),
            "compute_p50_us": round(self.percentile("compute", 50), 1),
            "compute_p99_us": round(self.percentile("compute", 99), 1),
            "deadline_misses": self.deadline_misses,
            "rcm_error_measured_max_mm": round(float(self.rcm_error_measured.max()) * 1e3, 4)
            if self.rcm_error_measured.size
            else None,
            "alarm": self.alarm,
            "stopped_at_rest": self.stopped_at_rest,
        }


class _Growable:
    """Append-only float array without per-append allocation."""

    def __init__(self, width: int = 0, capacity: int = 16384) -> None:
        self.width = width
        self.n = 0
        self.a = np.zeros((capacity, width) if width else capacity)

    def append(self, x: Any) -> None:
        if self.n == self.a.shape[0]:
            self.a = np.concatenate([self.a, np.zeros_like(self.a)])
        self.a[self.n] = x
        self.n += 1

    def array(self) -> np.ndarray:
        return self.a[: self.n].copy()


class ControlLoop:
    """Runs the controller on a robot at its control rate.

    Args:
        robot: A :class:`~lapwrench.robot.interface.RobotInterface` (Franka or simulation).
        controller: The controller (reset by :meth:`start` at the robot's measured pose).
        supervisor: The safety supervisor every command passes through.
        sources: Sensor buffers.
        ages: Maximum sample ages.
        logger: Optional MCAP logger.
        command_hook: Test seam for fault injection: ``f(k, q_ref) -> q_ref`` replaces the
            controller's command of cycle ``k`` before the supervisor sees it.
        compute_hook: Test seam: called with ``k`` inside the measured compute time.
        stop_timeout: Robot seconds allowed for the final stop to come to rest.
        switch_interval: Python's thread switch interval (s) while :meth:`run` runs (restored
            afterwards); ``None`` leaves it alone. See :meth:`run` for why.
        pre_cycle: Called with the ``time.monotonic()`` of each cycle right after ``robot.read()``
            and before the sensor frame is built (inside the measured compute time): the
            real-time process drains the F/T socket and checks its peers' heartbeats there
            (:mod:`lapwrench.hardware.rt_process`).
        gc_freeze: Freeze and disable Python's cyclic garbage collector for :meth:`run`
            (``gc.collect(); gc.freeze(); gc.disable()``; re-enabled afterwards).
    """

    def __init__(
        self,
        robot: RobotInterface,
        controller: Controller,
        supervisor: SafetySupervisor,
        sources: Sources | None = None,
        *,
        ages: SourceAges | None = None,
        logger: RunLogger | None = None,
        command_hook: Callable[[int, Vec], Vec] | None = None,
        compute_hook: Callable[[int], None] | None = None,
        stop_timeout: float = 5.0,
        switch_interval: float | None = 1e-4,
        pre_cycle: Callable[[float], None] | None = None,
        gc_freeze: bool = False,
    ) -> None:
        if switch_interval is not None and not (math.isfinite(switch_interval) and switch_interval > 0):
            raise ValueError(f"switch_interval must be a positive number of seconds, got {switch_interval!r}")
        self.robot = robot
        self.controller = controller
        self.supervisor = supervisor
        self.sources = sources or Sources()
        self.ages = ages or SourceAges()
        self.logger = logger
        self.command_hook = command_hook
        self.compute_hook = compute_hook
        self.stop_timeout = stop_timeout
        self.switch_interval = switch_interval
        self.pre_cycle = pre_cycle
        self.gc_freeze = gc_freeze
        self._t0 = 0.0
        self._fresh: dict[str, bool] = {}
        self.last_result: TickResult | None = None
        self.last_reading: RobotReading | None = None
        self._controller_failed = False
        self._started = False

    # -- helpers ------------------------------------------------------------------------------
    def session_time(self, now: float | None = None) -> float:
        return (time.monotonic() if now is None else now) - self._t0

    def _tick(self, frame: SensorFrame) -> TickResult | None:
        """The controller's tick; an exception becomes a supervisor alarm (None), never a crash.

        After a failed tick the controller is not called again in this run: the supervisor's stop
        brings the arm to rest.
        """
        if self._controller_failed:
            return None
        try:
            return self.controller.tick(frame)
        except Exception as exc:
            self._controller_failed = True
            self.supervisor.raise_alarm(frame.time, "controller_error", f"{type(exc).__name__}: {exc}")
            return None

    def _note_freshness(self, t: float, name: str, fresh: bool) -> None:
        was = self._fresh.get(name)
        if was is None or was != fresh:
            self._fresh[name] = fresh
            if not fresh:
                self._event(t, "input_stale", f"{name}: no sample newer than the max age; its wrench is off")
            elif was is not None:
                self._event(t, "input_fresh", f"{name}: fresh again")

    def _event(self, t: float, kind: str, message: str) -> None:
        self.supervisor.event(t, kind, message)

    def _frame(self, now: float, reading: RobotReading) -> SensorFrame:
        t = now - self._t0
        src, ages = self.sources, self.ages
        ft = tactile = instruments = None
        if src.ft is not None:
            s = src.ft.get_fresh(ages.ft, now)
            self._note_freshness(t, "ft", s is not None)
            if s is not None:
                ft = ForceTorqueReading(s.value.force, s.value.torque, s.timestamp - self._t0)
        if src.tactile is not None:
            s = src.tactile.get_fresh(ages.tactile, now)
            self._note_freshness(t, "tactile", s is not None)
            if s is not None:
                tactile = TactileReading(np.asarray(s.value.values, dtype=float), s.timestamp - self._t0)
        if src.instruments is not None:
            s = src.instruments.get_fresh(ages.instruments, now)
            self._note_freshness(t, "instruments", s is not None)
            if s is not None:
                instruments = InstrumentObservation(s.value.points, s.timestamp - self._t0)
        return SensorFrame(time=t, ft=ft, tactile=tactile, instruments=instruments, robot=reading)

    # -- life cycle ---------------------------------------------------------------------------
    def start(self, p_R: Vec | None = None) -> RobotReading:
        """Connect the robot, reset the controller at its pose and start supervision."""
        reading = self.robot.connect()
        self._t0 = time.monotonic()
        self.controller.reset(reading.q, p_R)
        self.supervisor.start(reading.q, 0.0)
        self._controller_failed = False
        self.last_reading = reading
        self._started = True
        return reading

    def run(
        self,
        duration: float | None = None,
        stop_event: threading.Event | None = None,
        *,
        disconnect: bool = True,
    ) -> LoopStats:
        """Run until ``duration`` robot seconds, ``stop_event``, or a supervisor alarm; then stop
        cleanly to rest and (by default) disconnect.

        The sensor threads share the interpreter with this loop, and pylibfranka's ``readOnce``
        keeps the GIL while it blocks for the next robot state (measured against franky-sim: a
        thread sleeping 1 ms woke 288 times in 2 s beside the loop, against 1571 alone). So the
        loop yields the GIL before each ``read`` and shortens the switch interval (100 µs by
        default): the same thread then woke 1151 times, and the F/T reader keeps its samples fresh.

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
        robot, ctrl, sup = self.robot, self.controller, self.supervisor
        dt = robot.dt
        assert ctrl.rcm is not None
        stats = LoopStats(q_start=np.array(self.last_reading.q if self.last_reading else np.zeros(7)))
        cyc, comp, rm, rr, cmds = _Growable(), _Growable(), _Growable(), _Growable(), _Growable(7)
        k = 0
        robot_t = 0.0
        stop_deadline: float | None = None
        wall0 = time.perf_counter()
        t_prev = None
        try:
            while True:
                if sup.at_rest and stop_deadline is not None:
                    break
                if stop_deadline is None and (
                    (duration is not None and robot_t >= duration - 1e-9)
                    or (stop_event is not None and stop_event.is_set())
                    or sup.state.value != "running"
                ):
                    sup.stop(self.session_time(), "end of run" if sup.state.value == "running" else "alarm")
                    stop_deadline = robot_t + self.stop_timeout
                if stop_deadline is not None and robot_t > stop_deadline:
                    self._event(self.session_time(), "stop_timeout", "the stop did not reach rest in time")
                    break

                time.sleep(0)  # let the sensor threads have the GIL before read() holds it
                reading = robot.read()
                t_read = time.perf_counter()
                now = time.monotonic()
                if self.pre_cycle is not None:
                    self.pre_cycle(now)
                frame = self._frame(now, reading)
                result = self._tick(frame)
                if result is not None:
                    for ev in result.events:
                        sup.counted_event(frame.time, f"input_{ev.source}", ev.message)
                    q_ref, p_R, residual, e_ref = result.q_ref, result.p_R, result.residual, result.rcm_error
                else:  # the supervisor is stopping on the alarm: it ignores the command
                    q_ref, p_R, residual, e_ref = reading.q, ctrl.rcm.p_R, None, math.nan
                if self.command_hook is not None:
                    q_ref = self.command_hook(k, q_ref)
                scope = measure_scope(ctrl.model, reading.q, p_R)
                e_meas = scope.rcm_error
                if self.compute_hook is not None:
                    self.compute_hook(k)
                compute = time.perf_counter() - t_read
                q_cmd = sup.filter(
                    frame.time,
                    q_ref,
                    rcm_error=e_meas,
                    depth=scope.depth,
                    residual=residual,
                    q_measured=reading.q,
                    compute_time=compute,
                    controller_stopping=result is not None and result.rcm_infeasible,
                )
                robot.command(q_cmd)
                cycle = 0.0 if t_prev is None else t_read - t_prev
                t_prev = t_read
                cyc.append(cycle * 1e6)
                comp.append(compute * 1e6)
                rm.append(e_meas)
                rr.append(e_ref)
                cmds.append(q_cmd)
                if self.logger is None:
                    sup.pending.clear()
                elif result is None:
                    self._flush_events()  # no controller output to record this cycle
                else:
                    self._log(k, frame, reading, result, q_cmd, e_meas, compute, cycle)
                if result is not None:
                    self.last_result = result
                self.last_reading = reading
                k += 1
                robot_t += dt
        except RobotError as exc:
            self._event(self.session_time(), "robot_error", str(exc))
            self._flush_events()
            if disconnect:
                self._safe_disconnect()
            raise
        self._flush_events()
        if disconnect:
            self._safe_disconnect()
        stats.cycles = k
        stats.cycle_us = cyc.array()[1:]
        stats.compute_us = comp.array()
        stats.rcm_error_measured = rm.array()
        stats.rcm_error_reference = rr.array()
        stats.commands = cmds.array()
        stats.p_R = ctrl.rcm.p_R.copy()
        stats.robot_time = robot_t
        stats.wall_time = time.perf_counter() - wall0
        stats.deadline_misses = sup.deadline_misses
        stats.alarm = sup.alarm_reason
        stats.stopped_at_rest = sup.at_rest
        return stats

    def _safe_disconnect(self) -> None:
        try:
            self.robot.disconnect()
        except Exception as exc:  # report, never mask the original outcome
            self._event(self.session_time(), "disconnect_error", str(exc))
            self._flush_events()

    def _flush_events(self) -> None:
        evs = self.supervisor.drain_events()
        if self.logger is not None:
            for e in evs:
                self.logger.event(e.time, e.kind, e.message)

    def _log(
        self,
        k: int,
        frame: SensorFrame,
        reading: RobotReading,
        r: TickResult,
        q_cmd: Vec,
        e_meas: float,
        compute: float,
        cycle: float,
    ) -> None:
        assert self.logger is not None
        ft, ta, ins = frame.ft, frame.tactile, frame.instruments
        self.logger.cycle(
            CycleRecord(
                t=frame.time,
                robot_time=reading.stamp,
                k=k,
                q=reading.q,
                dq=reading.dq,
                tau_J=getattr(self.robot, "tau_J", None),
                external_force=reading.external_force,
                ft_force=None if ft is None else ft.force,
                ft_torque=None if ft is None else ft.torque,
                tactile=None if ta is None else ta.values,
                instruments=None if ins is None else ins.points,
                wrenches=r.wrenches,
                mode=r.mode,
                delta=r.delta,
                contacts=r.contacts,
                p_R=r.p_R,
                e_R=r.e_R,
                rcm_error=r.rcm_error,
                rcm_error_measured=e_meas,
                q_ref=r.q_ref,
                q_cmd=q_cmd,
                supervisor=self.supervisor.state.value,
                alarm=self.supervisor.alarm,
                compute_us=compute * 1e6,
                cycle_us=cycle * 1e6,
            )
        )
        for e in self.supervisor.drain_events():
            self.logger.event(e.time, e.kind, e.message)
