"""The parent side of the real-time process: :class:`RtProcess` spawns the child, feeds it, drains
its log and watches its exit code and heartbeat."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import threading
import time
from typing import Any

import numpy as np

from lapwrench.buffer import LatestValue
from lapwrench.hardware.rt.bus import (
    BEAT_CHILD,
    BEAT_DETECTOR,
    BEAT_PARENT,
    CTL_PHASE,
    CTL_STOP,
    PHASE_READY,
    PHASE_RUNNING,
    TACTILE_N,
    bus_layout,
    input_slot,
)
from lapwrench.hardware.rt.child import _child_main
from lapwrench.hardware.rt.codec import INTERN, CycleCodec
from lapwrench.hardware.rt.peers import PeerSpec
from lapwrench.hardware.rt.spec import RtProcessError, RtResult, RtSpec, _error
from lapwrench.hardware.shm import Bus, unpack_event
from lapwrench.spawn import ensure_resource_tracker, quiet_process, start_quiet


class RtProcess:
    """Runs the control loop of ``spec`` in a spawned process and serves it from this one.

    Args:
        spec: What the child builds.
        tactile: The tactile latest-value buffer to feed (``None``: no tactile source).
        inputs: The registered inputs' driver buffers to feed, by name (``spec.inputs`` names them).
        logger: A :class:`~lapwrench.hardware.log.RunLogger` (or duck-typed) for cycles and events.
        detector_pid: The detector process the child should watch (its slot is fed by it).
        feeder: Run the parent's feeder thread (tactile slot + parent heartbeat). Tests turn it
            off and feed the bus from another process, whose pid is then ``feeder_pid``.
        feeder_pid: The process whose heartbeat the child watches as its feeder (default: this one).
        child_timeout: Child heartbeat age (s) that counts as a hang.
        connect_timeout: Seconds the child may take from "go" to its first cycle (robot connect).
        feed_period: Feeder period (s).
        stop_wait: Wall seconds the child's loop may take from the stop request to its end (its own
            stop deadline is ``spec.stop_timeout`` of robot time); beyond that it counts as hung and
            is killed, so a requested stop is bounded even if the child keeps beating.
    """

    def __init__(
        self,
        spec: RtSpec,
        *,
        tactile: LatestValue[Any] | None = None,
        inputs: dict[str, LatestValue[Any]] | None = None,
        logger: Any = None,
        detector_pid: int | None = None,
        feeder: bool = True,
        feeder_pid: int | None = None,
        child_timeout: float = 0.5,
        connect_timeout: float = 60.0,
        feed_period: float = 0.001,
        stop_wait: float = 30.0,
        start_method: str = "spawn",
    ) -> None:
        if start_method not in ("spawn", "forkserver"):
            raise ValueError("the real-time process is started with 'spawn' or 'forkserver', never 'fork'")
        self.spec = spec
        self.tactile = tactile
        self.inputs = dict(inputs or {})
        missing = sorted({name for name, _, _ in spec.inputs} - set(self.inputs))
        if missing:
            raise ValueError(f"no driver buffer for the registered inputs {missing}")
        self.logger = logger
        self.detector_pid = detector_pid
        self.feeder = feeder
        self.feeder_pid = os.getpid() if feeder_pid is None else feeder_pid
        self.child_timeout = child_timeout
        self.connect_timeout = connect_timeout
        self.feed_period = feed_period
        self.stop_wait = stop_wait
        self.ctx = mp.get_context(start_method)
        ensure_resource_tracker()  # the bus is registered with it: a closed terminal must not end it
        self.bus = Bus.create(bus_layout(spec.log_rows, spec.event_rows, spec.input_slots))
        self.codec = CycleCodec()
        self.proc: Any = None
        self.ready: dict[str, Any] = {}
        self.events: list[tuple[float, str, str]] = []
        self.cycles_logged = 0
        self._conn: Any = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._drain_lock = threading.Lock()
        self._closed = False

    @property
    def bus_name(self) -> str:
        return self.bus.name

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def peers(self) -> list[PeerSpec]:
        out = [PeerSpec("feeder", BEAT_PARENT, self.spec.feeder_timeout, self.feeder_pid)]
        if self.detector_pid is not None:
            out.append(PeerSpec("detector", BEAT_DETECTOR, self.spec.detector_timeout, self.detector_pid))
        return out

    # -- start-up ----------------------------------------------------------------------------------
    def start(self, timeout: float = 180.0) -> dict[str, Any]:
        """Spawn the child and wait until it has built everything (devices checked, F/T tared).

        Raises:
            RtProcessError: it failed or died (``kind`` in ``.kind``: robot, device, internal, died).
        """
        parent_conn, child_conn = self.ctx.Pipe()
        proc = quiet_process(  # SIGINT ignored there: Ctrl-C is this process's to handle (it asks for the stop)
            self.ctx, _child_main, (self.spec, self.bus.name, child_conn, self.peers()), name="lapwrench-rt",
            daemon=True,
        )
        self.bus["beat"][BEAT_PARENT] = time.monotonic()
        try:
            start_quiet(proc)  # spawn pickles the spec: a factory that does not pickle fails here
        except BaseException as exc:
            if proc.pid is not None:  # started, then a signal's handler raised: close() stops it
                self.proc, self._conn = proc, parent_conn
                child_conn.close()
                raise
            parent_conn.close()
            child_conn.close()
            if not isinstance(exc, Exception):
                raise
            why = f"{type(exc).__name__}: {exc}"
            raise _error("internal", f"the real-time process could not be started: {why}") from exc
        self.proc, self._conn = proc, parent_conn  # only a started process: close() joins it
        child_conn.close()
        self._start_threads()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if parent_conn.poll(0.05):
                msg = self._recv()
                if msg[0] == "ready":
                    self.ready = msg[1]
                    return self.ready
                if msg[0] == "error" and msg[1] == "died":
                    raise self._died("during start-up")
                self._raise_child_error(msg)
            if self.proc.exitcode is not None:
                raise self._died("during start-up")
        self.kill()
        raise _error("internal", f"the real-time process did not get ready within {timeout:.0f} s")

    def _recv(self) -> Any:
        try:
            return self._conn.recv()
        except (EOFError, OSError):
            return ("error", "died", "the real-time process closed its pipe")

    def _raise_child_error(self, msg: Any) -> None:
        if msg[0] == "error":
            self.drain()
            raise _error(msg[1], msg[2])
        raise _error("internal", f"unexpected message from the real-time process: {msg[0]!r}")

    def _died(self, when: str) -> RtProcessError:
        self.proc.join(2.0)  # its pipe closes just before it can be reaped
        code = self.proc.exitcode
        how = f"killed by {signal.Signals(-code).name}" if code is not None and code < 0 else f"exit code {code}"
        msg = (
            f"the real-time process (pid {self.proc.pid}) died {when} ({how}); nothing commands the robot"
            " any more: a Franka stops by itself when commands stop (libfranka"
            " communication_constraints_violation)"
        )
        self._parent_event("rt_process_died", msg)
        self.drain()
        return _error("died", msg)

    def _parent_event(self, kind: str, message: str) -> None:
        t = time.monotonic()
        self.events.append((t, kind, message))
        if self.logger is not None:
            with contextlib.suppress(Exception):
                self.logger.event(self._session_time(t), kind, message)

    def _session_time(self, t: float) -> float:
        return t - getattr(self, "_t_go", t)

    # -- the run -------------------------------------------------------------------------------------
    def run(self, duration: float | None = None, stop_event: Any = None, *, script_t0: float | None = None) -> RtResult:
        """Let the child connect and run; serve it until it is done.

        ``stop_event.is_set()`` requests the child's clean stop to rest (a signal in the CLI); its
        ``reason`` attribute, if any, is logged with the ``stop_requested`` event. From the request
        on, the child's loop has ``stop_wait`` seconds to end.

        Raises:
            RtProcessError: the child died, hung, or reported a robot/device/internal error.
        """
        if self.proc is None:
            self.start()
        self._t_go = time.monotonic()
        ctl, beat = self.bus["ctl"], self.bus["beat"]
        stop_sent: float | None = None
        running_since: float | None = None
        try:
            try:
                self._conn.send(("go", script_t0, self.spec.duration if duration is None else duration))
            except OSError:  # it ended while it waited for the go (a stop request, a signal): nothing runs
                raise self._died("before the go") from None
            while True:
                if stop_event is not None and stop_sent is None and stop_event.is_set():
                    ctl[CTL_STOP] = 1
                    stop_sent = time.monotonic()
                    reason = getattr(stop_event, "reason", None) or "stop requested"
                    self._parent_event("stop_requested", f"{reason}: stopping to rest")
                if self._conn.poll(0.01):
                    msg = self._recv()
                    if msg[0] == "done":
                        self.proc.join(10.0)
                        self._stop_threads()
                        return RtResult(msg[1], msg[2])
                    if msg[1] == "died":
                        raise self._died("during the run")
                    self._raise_child_error(msg)
                if self.proc.exitcode is not None:
                    if self._conn.poll(0.2):
                        continue  # its last message is still in the pipe
                    raise self._died("during the run")
                phase = ctl[CTL_PHASE]
                if phase == PHASE_READY and time.monotonic() - self._t_go > self.connect_timeout:
                    msg = (
                        f"the real-time process (pid {self.proc.pid}) did not start its loop within"
                        f" {self.connect_timeout:.0f} s of the go (robot connect hung?); killed"
                    )
                    self._parent_event("rt_process_hung", msg)
                    self.kill()
                    self.drain()
                    raise _error("hung", msg)
                if phase == PHASE_RUNNING and running_since is None:
                    running_since = time.monotonic()
                if (
                    running_since is not None
                    and stop_sent is not None
                    and phase == PHASE_RUNNING
                    and time.monotonic() - max(stop_sent, running_since) > self.stop_wait
                ):  # counted from the request, or from the loop's start if asked during the robot connect
                    msg = (
                        f"the real-time process (pid {self.proc.pid}) did not end its stop within"
                        f" {self.stop_wait:.0f} s of the request; killed. A Franka stops by itself when commands"
                        " stop (libfranka communication_constraints_violation)"
                    )
                    self._parent_event("rt_process_hung", msg)
                    self.kill()
                    self.drain()
                    raise _error("hung", msg)
                if phase == PHASE_RUNNING:
                    age = time.monotonic() - float(beat[BEAT_CHILD])
                    if age > self.child_timeout:
                        msg = (
                            f"the real-time process (pid {self.proc.pid}) sent no heartbeat for"
                            f" {age * 1e3:.0f} ms (> {self.child_timeout * 1e3:.0f} ms): hung; killed. A Franka"
                            " stops by itself when commands stop (libfranka communication_constraints_violation)"
                        )
                        self._parent_event("rt_process_hung", msg)
                        self.kill()
                        self.drain()
                        raise _error("hung", msg)
        finally:
            self._stop_threads()

    # -- feeder and log drain ------------------------------------------------------------------------
    def _start_threads(self) -> None:
        self._stop.clear()
        if self.feeder:
            self._threads.append(threading.Thread(target=self._feed, name="lapwrench-rt-feeder", daemon=True))
        self._threads.append(threading.Thread(target=self._drain_loop, name="lapwrench-rt-drain", daemon=True))
        for t in self._threads:
            t.start()

    def _stop_threads(self) -> None:
        self._stop.set()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(2.0)
        self._threads = []
        self.drain()

    def _feed(self) -> None:
        beat = self.bus["beat"]
        slot = self.bus.slot("tactile")
        extra = [(self.inputs[name], self.bus.slot(input_slot(name)), shape) for name, shape, _ in self.spec.inputs]
        seen = [0] * len(extra)
        last = 0
        while not self._stop.is_set():
            beat[BEAT_PARENT] = time.monotonic()
            src = self.tactile
            if src is not None:
                s = src.get()
                if s is not None and s.seq != last:
                    last = s.seq
                    with contextlib.suppress(Exception):  # a malformed frame is not fed
                        slot.write(np.asarray(s.value.values, dtype=float).reshape(TACTILE_N), s.timestamp)
            for i, (buffer, input_slot_, shape) in enumerate(extra):  # registered inputs, as the tactile frames
                s = buffer.get()
                if s is not None and s.seq != seen[i]:
                    seen[i] = s.seq
                    with contextlib.suppress(Exception):  # a value of the wrong shape or type is not fed
                        input_slot_.write(np.asarray(s.value, dtype=float).reshape(shape), s.timestamp)
            self._stop.wait(self.feed_period)

    def _drain_loop(self) -> None:
        while not self._stop.wait(0.01):
            self.drain()

    def set_logger(self, logger: Any) -> None:
        """Log from now on; the events received so far are written first."""
        with self._drain_lock:
            for t, kind, message in self.events:
                with contextlib.suppress(Exception):
                    logger.event(t, kind, message)
            self.logger = logger

    def drain(self) -> int:
        """Move the child's events and cycle records to the logger; returns the cycles moved."""
        with self._drain_lock:
            log, events = self.bus.ring("log"), self.bus.ring("events")
            rows = log.take()  # first the cycles' index, then every event announced before them
            for ev in events.take():
                t, kind, message = unpack_event(ev)
                if kind == INTERN:
                    self.codec.learn(message)
                    continue
                self.events.append((t, kind, message))
                if self.logger is not None:
                    with contextlib.suppress(Exception):
                        self.logger.event(t, kind, message)
            if self.logger is not None:
                for row in rows:
                    with contextlib.suppress(Exception):
                        self.logger.cycle(self.codec.decode(row))
            self.cycles_logged += len(rows)
            return len(rows)

    # -- shut-down -----------------------------------------------------------------------------------
    def request_stop(self) -> None:
        self.bus["ctl"][CTL_STOP] = 1

    def kill(self) -> None:
        """SIGKILL the child (a hung one) and reap it."""
        if self.proc is not None and self.proc.exitcode is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.join(5.0)

    def close(self, timeout: float = 10.0) -> None:
        """Stop the child (stop request, then SIGTERM, then SIGKILL), the threads, and free the bus.
        A second call does nothing."""
        if self._closed:
            return
        self._closed = True
        if self.proc is not None and self.proc.exitcode is None:
            self.request_stop()
            if self._conn is not None:
                with contextlib.suppress(Exception):
                    self._conn.send(("quit", None))
            self.proc.join(timeout)
            if self.proc.exitcode is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.proc.pid, signal.SIGTERM)
                self.proc.join(2.0)
            self.kill()
        self._stop_threads()
        if self._conn is not None:
            with contextlib.suppress(Exception):
                self._conn.close()
            self._conn = None
        self.bus.close()

    def __enter__(self) -> RtProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
