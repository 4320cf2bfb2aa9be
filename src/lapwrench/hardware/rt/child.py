"""The real-time child: its entry point (:func:`_child_main`, spawned by
:class:`~lapwrench.hardware.rt.parent.RtProcess`) and the hooks it runs each cycle."""

from __future__ import annotations

import contextlib
import math
import multiprocessing as mp
import os
import signal
import time
import traceback
import warnings
from typing import Any

import numpy as np

from lapwrench.hardware.rt.bus import (
    BEAT_CHILD,
    BEAT_PARENT,
    CTL_CYCLES,
    CTL_PHASE,
    CTL_STOP,
    PHASE_DONE,
    PHASE_READY,
    PHASE_RUNNING,
    bus_layout,
    input_slot,
)
from lapwrench.hardware.rt.codec import ShmLogSink
from lapwrench.hardware.rt.inputs import ShmInput
from lapwrench.hardware.rt.options import apply_realtime, lock_memory
from lapwrench.hardware.rt.peers import PeerSpec, PeerWatch
from lapwrench.hardware.rt.spec import FtSpec, RtSpec
from lapwrench.hardware.shm import Bus
from lapwrench.loop_stats import Growable
from lapwrench.robot.errors import RobotError

FT_CATCH_UP_S = 0.005
"""A cycle that starts more than this after the last F/T drain (the previous cycle came late: a stall of
the robot's side) drains the socket again before its tick, so the F/T data a tick reads is never more
than this older than a drain at the tick would give (a quarter of the default 20 ms maximum age, well
inside the box's own filter delay for a hand's push). At control rates under 1 kHz, five cycle periods."""

FT_DRAIN_BUDGET = 32
"""Datagrams the drain after each command reads at most (a 1 kHz box sends one a cycle). A flood from the
box's address (junk costs about 5 µs a datagram to reject) holds a cycle for a bounded time; the rest
stays queued, and what is published carries its arrival stamp, so a backlog reads as stale."""

PEER_CHECK_EVERY = 4
"""The peer watch runs after every this many commands (and before the first cycle): a helper that exited
is noticed within this many cycles (its pidfd), a hang when its heartbeat is at most this many cycles older
than its timeout (0.5 s, 1 s). A check is a system call (the pidfds' poll) and the heartbeats' ages: 3 µs
p50 with the caches cold, every cycle for nothing."""

FT_CATCH_UP_BUDGET = 256
"""Datagrams the catch-up drain after a late cycle reads at most: about what the socket's default buffer
holds (the kernel drops what comes beyond), so the tick after a stall reads the newest record there is."""


class _CycleHooks:
    """The child's work around each cycle.

    :meth:`after_command` (the loop's ``after_command``): heartbeat, F/T drain, shared inputs, peer
    watch (every :data:`PEER_CHECK_EVERY` th call), after the command is sent, in the slack before the next
    state; the next tick reads what they gathered, under 1 ms older. Once before the first cycle too. Each
    call is timed (:attr:`hook_us`): part of the cycle's work, though not of the command's latency.

    :meth:`before_tick` (the loop's ``pre_cycle``): the cycle counted; after a late cycle, the F/T drain
    again (:data:`FT_CATCH_UP_S`); then the F/T sample the tick will read is counted fresh or not.
    """

    def __init__(
        self, bus: Bus, ft: Any, ft_max_age: float, inputs: dict[str, ShmInput], watch: PeerWatch, dt: float = 0.001,
    ) -> None:
        self.ctl, self.beat = bus["ctl"], bus["beat"]
        # written every cycle: through memoryviews, which store a Python number without numpy's item machinery
        # (numpy's stubs give arrays the buffer protocol only from Python 3.12 on)
        self._ctl: memoryview[int] = memoryview(self.ctl)  # type: ignore[arg-type]
        self._beat: memoryview[float] = memoryview(self.beat)  # type: ignore[arg-type]
        self.ft, self.ft_max_age = ft, ft_max_age
        self.inputs = inputs
        self.watch = watch
        self.loop: Any = None
        self.cycles = 0
        self.ft_fresh = 0
        self.ft_datagrams = 0
        self.ft_catch_ups = 0
        self.fault: str | None = None
        self.hook_us = Growable()  # the time each after_command took (µs)
        self._commands = 0  # after_command calls: the peer watch runs on every PEER_CHECK_EVERY-th
        self._drained_at = -math.inf
        self._catch_up_s = max(FT_CATCH_UP_S, 5.0 * dt)

    def _alarm(self, now: float, kind: str, message: str) -> None:
        if self.fault is None:
            self.fault = f"{kind}: {message}"
            self.loop.supervisor.raise_alarm(self.loop.session_time(now), kind, message)

    def before_tick(self, now: float) -> None:
        self.cycles += 1
        self._ctl[CTL_CYCLES] = self.cycles
        ft = self.ft
        if ft is None:
            return
        if now - self._drained_at > self._catch_up_s:
            self._drain(ft, FT_CATCH_UP_BUDGET)
            self.ft_catch_ups += 1
        s = ft.buffer.get()
        if s is not None and now - s.timestamp <= self.ft_max_age:
            self.ft_fresh += 1

    def after_command(self, now: float) -> None:
        t0 = time.perf_counter()
        self._after_command(now)
        self.hook_us.append((time.perf_counter() - t0) * 1e6)

    def _drain(self, ft: Any, budget: int) -> None:
        """The F/T socket drained (at most ``budget`` datagrams), its newest record stamped with its arrival
        on the loop's clock (``time.monotonic``), not with the cycle's time."""
        self.ft_datagrams += ft.drain(max_datagrams=budget)
        self._drained_at = time.monotonic()

    def _after_command(self, now: float) -> None:
        self._beat[BEAT_CHILD] = now
        ft = self.ft
        if ft is not None:
            self._drain(ft, FT_DRAIN_BUDGET)
        for inp in self.inputs.values():
            problem = inp.refresh(now)
            if problem is not None:
                inp.kill()
                self._alarm(now, "ipc_corrupt", f"{problem}; its input is off")
        k = self._commands
        self._commands = k + 1
        if k % PEER_CHECK_EVERY:
            return
        hit = self.watch.check(now)
        if hit is not None:
            message, peer = hit
            for name, inp in self.inputs.items():  # the parent feeds tactile and the registered inputs
                if (name == "instruments") != (peer.beat == BEAT_PARENT):
                    inp.kill()
            kind = "peer_died" if "exited" in message else "peer_hung"
            self._alarm(now, kind, f"{message}; its inputs are stale")
            self.watch.forget(peer)

    def report(self) -> dict[str, Any]:
        return {
            "ft_fresh_cycles": self.ft_fresh,
            "hook_cycles": self.cycles,
            "ft_datagrams": self.ft_datagrams,
            "ft_catch_ups": self.ft_catch_ups,
            "peer_fault": self.fault,
            "hook_us": self.hook_us.array(),
            "torn_reads": {k: v.torn for k, v in self.inputs.items()},
        }


class _StopFlag:
    """``is_set()`` for ControlLoop.run: the parent's stop request, or a SIGTERM or SIGHUP to this
    process (``signal``: its name)."""

    def __init__(self, ctl: np.ndarray) -> None:
        self.ctl = ctl
        self._ctl: memoryview[int] = memoryview(ctl)  # type: ignore[arg-type]  # asked every cycle: no numpy item access
        self.signal: str | None = None

    def is_set(self) -> bool:
        return self.signal is not None or self._ctl[CTL_STOP] != 0


def _open_ft(spec: FtSpec) -> Any:
    from lapwrench.drivers.ft import AtiNetFTSensor, OnRobotHexSensor

    cls = OnRobotHexSensor if spec.kind == "hex" else AtiNetFTSensor
    ft = cls(spec.host, spec.port)
    ft.start_polled()
    if spec.tare:
        try:
            ft.tare(n_samples=spec.tare_samples)
        except BaseException:
            ft.stop()
            raise
    return ft


def _warm_up(ctrl: Any, spec: RtSpec) -> None:
    """Run the loop's own per-cycle code once outside the loop (first calls compile or allocate:
    measured 22 ms for the first ``measure_scope``), on throwaway state."""
    from lapwrench.robot.description import ARM_SPECS
    from lapwrench.safety.supervisor import SafetySupervisor, measure_scope

    q = np.array(ARM_SPECS[ctrl.model.kind].home_pose, dtype=float)
    scope = measure_scope(ctrl.model, q, np.zeros(3))
    sup = SafetySupervisor(ctrl.model.limits, spec.cfg.robot.dt, spec.supervisor)
    sup.start(q)
    for _ in range(3):
        sup.filter(0.0, q, rcm_error=scope.rcm_error, depth=scope.depth, residual=np.zeros(3), q_measured=q,
                   compute_time=0.0)


def _child_main(spec: RtSpec, bus_name: str, conn: Any, peers: list[PeerSpec]) -> None:
    """Entry point of the real-time process."""
    from lapwrench.controller import Controller
    from lapwrench.drivers.base import DeviceError
    from lapwrench.hardware.runner import ControlLoop, Sources
    from lapwrench.safety.supervisor import SafetySupervisor

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which asks for the stop
    stop_flag: _StopFlag | None = None
    pending: list[str] = []

    def on_term(signum: int, frame: Any) -> None:
        # SIGTERM, or SIGHUP (a closed terminal hangs up the whole process group): the stop to rest,
        # never the default death that would leave the arm without commands mid-motion
        if not pending:
            pending.append(signal.Signals(signum).name)
        if stop_flag is not None and stop_flag.signal is None:
            stop_flag.signal = pending[0]

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGHUP, on_term)
    bus = ft = watch = None
    try:
        bus = Bus.attach(bus_name, bus_layout(spec.log_rows, spec.event_rows, spec.input_slots))
        ctl = bus["ctl"]
        stop_flag = _StopFlag(ctl)
        stop_flag.signal = pending[0] if pending else None
        sink = ShmLogSink(bus.ring("log"), bus.ring("events"), cycles=spec.log_cycles)
        problems = apply_realtime(spec.rt)
        for p in problems:
            sink.event(0.0, "rt_setup", p)
            if spec.rt.warn:
                warnings.warn(f"lapwrench real-time process: {p}", RuntimeWarning, stacklevel=1)
        ctrl = Controller(spec.cfg)
        sup = SafetySupervisor(ctrl.model.limits, spec.cfg.robot.dt, spec.supervisor)
        _warm_up(ctrl, spec)
        devices: dict[str, str] = {}
        if spec.ft is not None:
            ft = _open_ft(spec.ft)
            devices["ft"] = ft.device
        robot = spec.robot_factory(spec.cfg, spec.script)
        inputs: dict[str, ShmInput] = {}
        if spec.tactile:
            inputs["tactile"] = ShmInput(bus.slot("tactile"), "tactile")
        if spec.instruments:
            inputs["instruments"] = ShmInput(bus.slot("instruments"), "instruments")
        for name, _, _ in spec.inputs:  # registered inputs the cues ask for, fed by the parent
            inputs[input_slot(name)] = ShmInput(bus.slot(input_slot(name)), name, registered=True)
        watch = PeerWatch(bus["beat"], peers)
        hooks = _CycleHooks(bus, ft, spec.ages.ft, inputs, watch, spec.cfg.robot.dt)
        sources = Sources(
            ft=None if ft is None else ft.buffer, tactile=inputs.get("tactile"), instruments=inputs.get("instruments"),
            extra={name: (inputs[input_slot(name)], max_age) for name, _, max_age in spec.inputs},
        )
        loop = ControlLoop(
            robot,
            ctrl,
            sup,
            sources,
            ages=spec.ages,
            logger=sink,  # type: ignore[arg-type]
            pre_cycle=hooks.before_tick,
            after_command=hooks.after_command,
            gc_freeze=spec.rt.gc_freeze,
            stop_timeout=spec.stop_timeout,
        )
        hooks.loop = loop
        extra = spec.loop_hook(loop) if spec.loop_hook is not None else None
        if spec.rt.lock_memory:  # everything built: what the loop has is locked in, and what it maps later
            problem = lock_memory()
            if problem is not None:
                problems.append(problem)
                sink.event(0.0, "rt_setup", problem)
                if spec.rt.warn:
                    warnings.warn(f"lapwrench real-time process: {problem}", RuntimeWarning, stacklevel=1)
        ctl[CTL_PHASE] = PHASE_READY
        conn.send(("ready", {"robot": getattr(robot, "device", type(robot).__name__), "devices": devices,
                             "rt_problems": problems, "pid": os.getpid()}))
        parent = mp.parent_process()
        while not conn.poll(0.02):  # wait for "go"; give up if the parent is gone
            bus["beat"][BEAT_CHILD] = time.monotonic()
            if (parent is not None and not parent.is_alive()) or stop_flag.is_set():
                return
        msg = conn.recv()
        if msg[0] != "go":
            return
        _, script_t0, duration = msg
        if spec.script is not None and script_t0 is not None:
            spec.script.t0 = script_t0
        loop.start(spec.p_R)
        if ft is not None:  # what queued up since the tare, read here rather than in the first cycle
            while ft.drain() > 0:
                pass
        now = time.monotonic()
        watch.arm(now)
        hooks.after_command(now)  # the inputs (and heartbeat) the first cycle's tick reads
        ctl[CTL_PHASE] = PHASE_RUNNING
        stats = loop.run(duration, stop_flag)  # type: ignore[arg-type]
        ctl[CTL_PHASE] = PHASE_DONE
        report = hooks.report()
        report.update(log_dropped=bus.ring("log").dropped, events_dropped=bus.ring("events").dropped,
                      encode_errors=sink.encode_errors, stop_signal=stop_flag.signal)
        if extra is not None and hasattr(extra, "report"):
            report.update(extra.report())
        conn.send(("done", stats, report))
    except RobotError as exc:
        _send(conn, ("error", "robot", str(exc)))
    except DeviceError as exc:
        _send(conn, ("error", "device", str(exc)))
    except BaseException as exc:  # anything else: reported, never a silent death
        _send(conn, ("error", "internal", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
    finally:
        if bus is not None:
            with contextlib.suppress(Exception):
                bus["ctl"][CTL_PHASE] = PHASE_DONE
        if watch is not None:
            watch.close()
        if ft is not None:
            with contextlib.suppress(Exception):
                ft.stop()
        if bus is not None:
            bus.close()


def _send(conn: Any, msg: Any) -> None:
    with contextlib.suppress(Exception):
        conn.send(msg)
