"""The 1 kHz control loop in its own process, isolated from the GIL of everything else.

Process layout (``lapwrench run`` by default)::

    parent (CLI, UI)                          real-time child (spawned, never forked)
    ----------------                          ---------------------------------------
    tactile serial reader ─┐                  robot (pylibfranka / franky-sim / SimRobot)
    feeder thread ─────────┼─ tactile slot ─▶ controller, supervisor
      (+ parent heartbeat) ┘                  F/T UDP socket, drained non-blocking each cycle
    camera ─▶ frame slot ─▶ detector process ─ instruments slot ─▶ (read each cycle)
    log drain thread ◀──── log ring + event ring ◀── ControlLoop's logger (never blocks)
    RunLogger (MCAP writer)
    monitor: child exit code + heartbeat       heartbeat, peer watch (pidfd + heartbeats)

All of it lives in one shared-memory :class:`~lapwrench.hardware.shm.Bus` (:func:`bus_layout`):
control words (stop request, phase, cycle count), heartbeat stamps (``time.monotonic()``, one clock
for all processes), the tactile and instrument latest-value slots (seqlocks, ≤ 16 points), and two
bounded rings from the child: cycle records (fixed float64 rows, :class:`CycleCodec`) and events
(fixed byte rows). A full ring drops and counts; the child never waits on the parent. A pipe carries
the start-up handshake (ready / go / error) and, once, the final :class:`LoopStats`.

What happens on each fault
--------------------------
* **Feeder (parent) dies** (crash, SIGKILL): the child polls the parent's pidfd each cycle → alarm
  ``peer_died`` at the next cycle → the supervisor's jerk-limited stop to rest → the child ends.
* **Feeder hangs** (deadlock, SIGSTOP, starved): its heartbeat is older than ``feeder_timeout``
  (default 0.5 s) → alarm ``peer_hung`` → stop to rest. In both cases the inputs it fed read as
  stale from then on. Before that, the tactile sample's own max age (0.1 s) has already switched
  the handle wrench off, as for any silent sensor; the timeout only decides when a silent *process*
  stops the arm. It is not shorter because the parent is an ordinary (not real-time) process: on
  this shared 2-core machine under load its feeder thread was seen to go 157 ms without running.
* **Detector process dies or hangs**: the same with its pid and ``detector_timeout`` (1.0 s; the
  instruments' max age, 0.2 s, switches the tracking wrench off first).
* **Corrupt shared memory** (a non-finite value, a point count out of range, a stamp in the
  future): alarm ``ipc_corrupt`` naming the slot → stop to rest. A slot left mid-write reads as
  stale.
* **Child dies or hangs**: the parent sees its exit code or a heartbeat older than
  ``child_timeout`` (0.5 s), logs ``rt_process_died``/``rt_process_hung`` and raises
  :class:`RtProcessError` (a hung child is killed). Nothing is left to command the robot: on a real
  Franka, libfranka's controller stops the arm by itself when commands stop arriving
  (``communication_constraints_violation``), which is the stop of last resort; franky-sim and the
  simulated robot just stop stepping.
* **Ctrl-C / SIGTERM in the parent**: the CLI sets the stop request in shared memory; the child's
  loop stops to rest through the supervisor, sends its statistics, and the parent flushes the log.
  The child ignores SIGINT (the terminal sends it to the whole process group) and treats its own
  SIGTERM as a stop request.

Real-time settings (:class:`RtOptions`): SCHED_FIFO and CPU affinity when permitted, one warning
when not (like panda-py), and the garbage collector frozen in the loop.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing as mp
import os
import select
import signal
import threading
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from lapwrench.drivers.buffer import LatestValue, Sample
from lapwrench.hardware.log import CycleRecord
from lapwrench.hardware.runner import LoopStats, SourceAges
from lapwrench.hardware.shm import Bus, Layout, Ring, SeqlockSlot, pack_event, unpack_event
from lapwrench.hardware.supervisor import SupervisorConfig
from lapwrench.robot.interface import RobotError
from lapwrench.sensors import InstrumentObservation

__all__ = [
    "MAX_POINTS",
    "CycleCodec",
    "FtSpec",
    "RtOptions",
    "RtProcess",
    "RtProcessError",
    "RtSpec",
    "apply_realtime",
    "bus_layout",
]

MAX_POINTS = 16
"""Instrument points the instruments slot holds (more detections are cut, best first)."""
TACTILE_N = 64
EVENT_BYTES = 320

# control words (int64) and heartbeat stamps (float64) on the bus
CTL_STOP, CTL_PHASE, CTL_CYCLES, CTL_DET_STOP, CTL_DET_FRAMES, CTL_DET_ERRORS = 0, 1, 2, 3, 4, 5
BEAT_PARENT, BEAT_CHILD, BEAT_DETECTOR = 0, 1, 2
PHASE_STARTING, PHASE_READY, PHASE_RUNNING, PHASE_DONE = 0, 1, 2, 3


def bus_layout(log_rows: int = 4096, event_rows: int = 1024) -> Layout:
    """The regions of the real-time bus (every process builds the same layout)."""
    return (
        Layout()
        .add("ctl", np.int64, (16,))
        .add("beat", np.float64, (8,))
        .slot("tactile", np.float64, (TACTILE_N,))
        .slot("instruments", np.float64, (MAX_POINTS, 2))
        .ring("log", np.float64, log_rows, CycleCodec.WIDTH)
        .ring("events", np.uint8, event_rows, EVENT_BYTES)
    )


class RtProcessError(RobotError):
    """The real-time process died, hung, or failed to start (a robot error for the CLI)."""


# -- cycle records as fixed float64 rows ------------------------------------------------------------
class CycleCodec:
    """Packs a :class:`~lapwrench.hardware.log.CycleRecord` into one float64 row and back.

    Optional vectors carry a presence flag (``None`` stays ``None``; NaN stays NaN). Strings (mode,
    supervisor state, wrench names) are interned: a new string is announced once on the event ring
    (kind ``__intern__``) before the first row that uses it.
    """

    N_WRENCH = 8
    _spec: tuple[tuple[str, str, int], ...] = (
        ("t", "f", 1), ("robot_time", "f", 1), ("k", "f", 1), ("q", "v", 7), ("dq", "v", 7),
        ("tau_J", "o", 7), ("external_force", "o", 3), ("ft_force", "o", 3), ("ft_torque", "o", 3),
        ("tactile", "o", TACTILE_N), ("instruments", "p", MAX_POINTS), ("wrenches", "w", N_WRENCH),
        ("mode", "s", 1), ("delta", "f", 1), ("contacts", "f", 1), ("p_R", "v", 3), ("e_R", "v", 3),
        ("rcm_error", "f", 1), ("rcm_error_measured", "n", 1), ("q_ref", "v", 7), ("q_cmd", "v", 7),
        ("supervisor", "s", 1), ("alarm", "f", 1), ("compute_us", "f", 1), ("cycle_us", "f", 1),
    )
    OFF: ClassVar[dict[str, int]] = {}
    WIDTH = 0

    @classmethod
    def _build(cls) -> None:
        o = 0
        for name, kind, n in cls._spec:
            cls.OFF[name] = o
            o += {"f": 1, "v": n, "o": 1 + n, "p": 1 + 2 * n, "w": 7 * n, "s": 1, "n": 2}[kind]
        cls.WIDTH = o

    def __init__(self, announce: Callable[[str, str], bool] | None = None) -> None:
        self.announce = announce
        self.tables: dict[str, list[str]] = {"mode": [], "supervisor": [], "wrench": []}
        self._index: dict[str, dict[str, int]] = {"mode": {}, "supervisor": {}, "wrench": {}}

    def intern(self, table: str, s: str) -> int:
        idx = self._index[table]
        i = idx.get(s)
        if i is None:
            if self.announce is not None and not self.announce(table, s):
                return -1  # not announced (event ring full): "?" in this row, announced again next time
            i = idx[s] = len(self.tables[table])
            self.tables[table].append(s)
        return i

    def learn(self, message: str) -> None:
        """Apply an ``__intern__`` announcement (``table:name``) on the decoding side."""
        table, _, name = message.partition(":")
        if table in self.tables and name not in self._index[table]:
            self._index[table][name] = len(self.tables[table])
            self.tables[table].append(name)

    def encode(self, row: np.ndarray, r: CycleRecord) -> None:
        off = self.OFF
        row[0] = r.t
        row[1] = r.robot_time
        row[2] = r.k
        row[off["q"] : off["q"] + 7] = r.q
        row[off["dq"] : off["dq"] + 7] = r.dq
        for name, n in (("tau_J", 7), ("external_force", 3), ("ft_force", 3), ("ft_torque", 3), ("tactile", TACTILE_N)):
            o = off[name]
            v = getattr(r, name)
            if v is None:
                row[o] = 0.0
            else:
                row[o] = 1.0
                row[o + 1 : o + 1 + n] = v
        o = off["instruments"]
        if r.instruments is None:
            row[o] = -1.0
        else:
            pts = np.asarray(r.instruments, dtype=float).reshape(-1, 2)[:MAX_POINTS]
            row[o] = len(pts)
            row[o + 1 : o + 1 + 2 * len(pts)] = pts.ravel()
        o = off["wrenches"]
        row[o : o + 7 * self.N_WRENCH : 7] = -2.0
        for i, (name, w) in enumerate(list(r.wrenches.items())[: self.N_WRENCH]):
            row[o + 7 * i] = self.intern("wrench", name)
            row[o + 7 * i + 1 : o + 7 * i + 7] = w
        row[off["mode"]] = self.intern("mode", r.mode)
        row[off["delta"]] = r.delta
        row[off["contacts"]] = r.contacts
        row[off["p_R"] : off["p_R"] + 3] = r.p_R
        row[off["e_R"] : off["e_R"] + 3] = r.e_R
        row[off["rcm_error"]] = r.rcm_error
        o = off["rcm_error_measured"]
        row[o] = 0.0 if r.rcm_error_measured is None else 1.0
        row[o + 1] = math.nan if r.rcm_error_measured is None else r.rcm_error_measured
        row[off["q_ref"] : off["q_ref"] + 7] = r.q_ref
        row[off["q_cmd"] : off["q_cmd"] + 7] = r.q_cmd
        row[off["supervisor"]] = self.intern("supervisor", r.supervisor)
        row[off["alarm"]] = 1.0 if r.alarm else 0.0
        row[off["compute_us"]] = r.compute_us
        row[off["cycle_us"]] = r.cycle_us

    def _name(self, table: str, x: float) -> str:
        t = self.tables[table]
        i = int(x)
        return t[i] if 0 <= i < len(t) else "?"

    def decode(self, row: np.ndarray) -> CycleRecord:
        off = self.OFF

        def opt(name: str, n: int) -> np.ndarray | None:
            o = off[name]
            return row[o + 1 : o + 1 + n].copy() if row[o] == 1.0 else None

        o = off["instruments"]
        n = int(row[o])
        inst = None if n < 0 else row[o + 1 : o + 1 + 2 * n].reshape(n, 2).copy()
        o = off["wrenches"]
        wr = {
            self._name("wrench", row[o + 7 * i]): row[o + 7 * i + 1 : o + 7 * i + 7].copy()
            for i in range(self.N_WRENCH)
            if row[o + 7 * i] >= -1
        }
        om = off["rcm_error_measured"]
        return CycleRecord(
            t=float(row[0]),
            robot_time=float(row[1]),
            k=int(row[2]),
            q=row[off["q"] : off["q"] + 7].copy(),
            dq=row[off["dq"] : off["dq"] + 7].copy(),
            tau_J=opt("tau_J", 7),
            external_force=opt("external_force", 3),
            ft_force=opt("ft_force", 3),
            ft_torque=opt("ft_torque", 3),
            tactile=opt("tactile", TACTILE_N),
            instruments=inst,
            wrenches=wr,
            mode=self._name("mode", row[off["mode"]]),
            delta=float(row[off["delta"]]),
            contacts=int(row[off["contacts"]]),
            p_R=row[off["p_R"] : off["p_R"] + 3].copy(),
            e_R=row[off["e_R"] : off["e_R"] + 3].copy(),
            rcm_error=float(row[off["rcm_error"]]),
            rcm_error_measured=float(row[om + 1]) if row[om] == 1.0 else None,
            q_ref=row[off["q_ref"] : off["q_ref"] + 7].copy(),
            q_cmd=row[off["q_cmd"] : off["q_cmd"] + 7].copy(),
            supervisor=self._name("supervisor", row[off["supervisor"]]),
            alarm=bool(row[off["alarm"]]),
            compute_us=float(row[off["compute_us"]]),
            cycle_us=float(row[off["cycle_us"]]),
        )


CycleCodec._build()
INTERN = "__intern__"


class ShmLogSink:
    """The child's logger (duck-typed :class:`~lapwrench.hardware.log.RunLogger`): rows into the
    bounded rings, never blocking; a full ring or a record that does not encode is counted."""

    def __init__(self, log: Ring, events: Ring, *, cycles: bool = True) -> None:
        self.log, self.events = log, events
        self.cycles = cycles
        self.codec = CycleCodec(self._announce)
        self.encode_errors = 0

    def _announce(self, table: str, name: str) -> bool:
        return self.event(0.0, INTERN, f"{table}:{name}")

    def cycle(self, record: CycleRecord) -> None:
        if not self.cycles:
            return
        row = self.log.reserve()
        if row is None:
            return
        try:
            self.codec.encode(row, record)
        except Exception:  # a record of an unexpected shape: dropped, counted, never raised
            self.encode_errors += 1
            return
        self.log.commit()

    def event(self, time: float, kind: str, message: str) -> bool:
        row = self.events.reserve()
        if row is None:
            return False
        pack_event(row, time, kind, message)
        self.events.commit()
        return True


# -- the child's inputs from shared memory ----------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Values:
    values: np.ndarray


class ShmInput:
    """A shared-memory slot seen by :class:`~lapwrench.hardware.runner.ControlLoop` as a
    latest-value buffer (``get_fresh``). :meth:`refresh` reads and checks the slot once per cycle
    (in the loop's ``pre_cycle``); it returns a message when the slot holds corrupt data."""

    def __init__(self, slot: SeqlockSlot, kind: str, clock: Callable[[], float] = time.monotonic) -> None:
        if kind not in ("tactile", "instruments"):
            raise ValueError(f"unknown shared input {kind!r}")
        self.slot, self.kind, self.clock = slot, kind, clock
        self._buf = np.empty_like(slot.data)
        self._seq = 0
        self._sample: Sample[Any] | None = None
        self.dead = False
        self.torn = 0

    @property
    def name(self) -> str:
        return self.kind

    def kill(self) -> None:
        """Its writer is gone: read as stale from now on."""
        self.dead = True
        self._sample = None

    def refresh(self, now: float) -> str | None:
        if self.dead:
            return None
        r = self.slot.read_into(self._buf)
        if r is None:
            if self.slot.seq & 1:
                self.torn += 1
            return None
        seq, stamp, count = r
        if seq == self._seq:
            return None
        self._seq = seq
        b = self._buf
        problem = None
        # compared with the clock read now, not the cycle's start: a writer may publish while this
        # process is preempted between the two (seen under load), which is no corruption
        if not (math.isfinite(stamp) and stamp <= self.clock() + 0.005):
            problem = f"sample stamp {stamp!r} is not a past monotonic time"
        elif self.kind == "tactile":
            if count != TACTILE_N or not np.all(np.isfinite(b)):
                problem = f"{count} values, non-finite: {int(np.sum(~np.isfinite(b)))}"
        elif not 0 <= count <= MAX_POINTS:
            problem = f"point count {count} outside [0, {MAX_POINTS}]"
        elif not np.all(np.isfinite(b[:count])):
            problem = "non-finite image point"
        if problem is not None:
            self._sample = None
            return f"{self.kind} slot: {problem}"
        if self.kind == "tactile":
            value: Any = _Values(b.copy())
        else:
            value = InstrumentObservation(b[:count].copy(), stamp)
        self._sample = Sample(value, stamp, seq)
        return None

    def get(self) -> Sample[Any] | None:
        return self._sample

    def get_fresh(self, max_age: float, now: float | None = None) -> Sample[Any] | None:
        s = self._sample
        if s is None or (time.monotonic() if now is None else now) - s.timestamp > max_age:
            return None
        return s


# -- peers and their heartbeats -------------------------------------------------------------------
@dataclass(frozen=True)
class PeerSpec:
    """A process the child depends on: its heartbeat stamp index on the bus, the heartbeat age
    that counts as a hang (s), and its pid (watched through a pidfd; ``None``: heartbeat only)."""

    name: str
    beat: int
    timeout: float
    pid: int | None = None


class PeerWatch:
    """Checks every peer each cycle: exited (pidfd readable) or heartbeat too old."""

    def __init__(self, beats: np.ndarray, peers: list[PeerSpec]) -> None:
        self.beats = beats
        self.peers = peers
        self._poll = select.poll()
        self._fd_peer: dict[int, PeerSpec] = {}
        self._kill_check: list[PeerSpec] = []
        for p in peers:
            if p.pid is None:
                continue
            try:
                fd = os.pidfd_open(p.pid)
            except (AttributeError, OSError):  # no pidfd (old kernel) or already gone
                if _pid_alive(p.pid):
                    self._kill_check.append(p)
                    continue
                fd = -1
            if fd >= 0:
                self._fd_peer[fd] = p
                self._poll.register(fd, select.POLLIN)
        self.armed_at = time.monotonic()

    def arm(self, now: float) -> None:
        """Heartbeats count from now on (the start-up is not a hang)."""
        self.armed_at = now

    def check(self, now: float) -> tuple[str, PeerSpec] | None:
        if self._fd_peer:
            for fd, _ev in self._poll.poll(0):
                p = self._fd_peer[fd]
                return f"{p.name} process (pid {p.pid}) exited", p
        for p in self._kill_check:
            if not _pid_alive(p.pid):  # type: ignore[arg-type]
                return f"{p.name} process (pid {p.pid}) exited", p
        for p in self.peers:
            last = max(float(self.beats[p.beat]), self.armed_at)
            if now - last > p.timeout:
                age = now - float(self.beats[p.beat]) if self.beats[p.beat] > 0 else math.inf
                return f"no heartbeat from the {p.name} for {age * 1e3:.0f} ms (> {p.timeout * 1e3:.0f} ms): hung", p
        return None

    def close(self) -> None:
        for fd in self._fd_peer:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fd_peer = {}


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


# -- real-time settings -----------------------------------------------------------------------------
@dataclass(frozen=True)
class RtOptions:
    """Scheduling of the real-time process.

    Attributes:
        fifo_priority: SCHED_FIFO priority (1-99) for the loop's thread; ``None``: don't ask.
        cpus: CPU ids to pin the real-time process to; ``None``: don't pin.
        gc_freeze: Freeze and disable the cyclic garbage collector during the run.
        warn: Print the one warning when a setting is not permitted (it is logged either way).
    """

    fifo_priority: int | None = 80
    cpus: tuple[int, ...] | None = None
    gc_freeze: bool = True
    warn: bool = True

    def __post_init__(self) -> None:
        if self.fifo_priority is not None and not 1 <= self.fifo_priority <= 99:
            raise ValueError(f"SCHED_FIFO priority must be in 1..99, got {self.fifo_priority}")


def apply_realtime(opts: RtOptions) -> list[str]:
    """Apply ``opts`` to the calling thread/process; a message for each setting not permitted."""
    problems: list[str] = []
    if opts.cpus is not None:
        try:
            os.sched_setaffinity(0, set(opts.cpus))
        except (OSError, ValueError) as exc:
            problems.append(f"CPU affinity {sorted(opts.cpus)} not applied ({exc})")
    if opts.fifo_priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(opts.fifo_priority))
        except (OSError, AttributeError) as exc:
            problems.append(
                f"SCHED_FIFO priority {opts.fifo_priority} not permitted ({type(exc).__name__}: {exc}); "
                "the control loop runs at normal priority and may miss deadlines on a busy machine. "
                "Grant real-time scheduling (e.g. 'ulimit -r 99' via /etc/security/limits.d, as the "
                "libfranka real-time setup does) or run on a PREEMPT_RT kernel."
            )
    return problems


# -- what the child builds --------------------------------------------------------------------------
@dataclass(frozen=True)
class FtSpec:
    """The handle F/T sensor the child opens (polled, no reader thread)."""

    kind: str  # "hex" or "ati"
    host: str
    port: int
    tare: bool = True
    tare_samples: int = 100


@dataclass
class RtSpec:
    """Everything the real-time child needs (pickled to a spawned process).

    ``robot_factory(cfg, script)`` builds the robot in the child (a module-level function or a
    ``functools.partial`` of one). ``loop_hook(loop)`` is a seam for tests and benchmarks, called on
    the built loop in the child; if it returns an object with ``report() -> dict``, that dict is
    merged into the child's final report.
    """

    cfg: Any
    robot_factory: Callable[[Any, Any], Any]
    supervisor: SupervisorConfig
    ages: SourceAges = field(default_factory=SourceAges)
    ft: FtSpec | None = None
    tactile: bool = True
    instruments: bool = False
    duration: float | None = None
    p_R: Any = None
    log_cycles: bool = True
    rt: RtOptions = field(default_factory=RtOptions)
    feeder_timeout: float = 0.5
    detector_timeout: float = 1.0
    stop_timeout: float = 5.0
    script: Any = None
    loop_hook: Callable[[Any], None] | None = None
    log_rows: int = 4096
    event_rows: int = 1024


class _CycleHooks:
    """The child's ``pre_cycle``: heartbeat, F/T drain, shared inputs, peer watch."""

    def __init__(self, bus: Bus, ft: Any, ft_max_age: float, inputs: dict[str, ShmInput], watch: PeerWatch) -> None:
        self.ctl, self.beat = bus["ctl"], bus["beat"]
        self.ft, self.ft_max_age = ft, ft_max_age
        self.inputs = inputs
        self.watch = watch
        self.loop: Any = None
        self.cycles = 0
        self.ft_fresh = 0
        self.ft_datagrams = 0
        self.fault: str | None = None

    def _alarm(self, now: float, kind: str, message: str) -> None:
        if self.fault is None:
            self.fault = f"{kind}: {message}"
            self.loop.supervisor.raise_alarm(self.loop.session_time(now), kind, message)

    def __call__(self, now: float) -> None:
        self.beat[BEAT_CHILD] = now
        self.cycles += 1
        self.ctl[CTL_CYCLES] = self.cycles
        ft = self.ft
        if ft is not None:
            self.ft_datagrams += ft.drain(now)
            s = ft.buffer.get()
            if s is not None and now - s.timestamp <= self.ft_max_age:
                self.ft_fresh += 1
        for inp in self.inputs.values():
            problem = inp.refresh(now)
            if problem is not None:
                inp.kill()
                self._alarm(now, "ipc_corrupt", f"{problem}; its input is off")
        hit = self.watch.check(now)
        if hit is not None:
            message, peer = hit
            for name in ("tactile",) if peer.beat == BEAT_PARENT else ("instruments",):
                if name in self.inputs:
                    self.inputs[name].kill()
            kind = "peer_died" if "exited" in message else "peer_hung"
            self._alarm(now, kind, f"{message}; its inputs are stale")
            self.watch.peers = [p for p in self.watch.peers if p is not peer]

    def report(self) -> dict[str, Any]:
        return {
            "ft_fresh_cycles": self.ft_fresh,
            "hook_cycles": self.cycles,
            "ft_datagrams": self.ft_datagrams,
            "peer_fault": self.fault,
            "torn_reads": {k: v.torn for k, v in self.inputs.items()},
        }


class _StopFlag:
    """``is_set()`` for ControlLoop.run: the parent's stop request or this process's SIGTERM."""

    def __init__(self, ctl: np.ndarray) -> None:
        self.ctl = ctl
        self.term = False

    def is_set(self) -> bool:
        return self.term or bool(self.ctl[CTL_STOP])


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
    from lapwrench.hardware.supervisor import SafetySupervisor, measure_scope
    from lapwrench.virtual import DEFAULT_Q0

    q = np.array(DEFAULT_Q0, dtype=float)
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
    from lapwrench.hardware.supervisor import SafetySupervisor

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which asks for the stop
    stop_flag: _StopFlag | None = None
    pending_term = [False]

    def on_term(signum: int, frame: Any) -> None:
        pending_term[0] = True
        if stop_flag is not None:
            stop_flag.term = True

    signal.signal(signal.SIGTERM, on_term)
    bus = ft = watch = None
    try:
        bus = Bus.attach(bus_name, bus_layout(spec.log_rows, spec.event_rows))
        ctl = bus["ctl"]
        stop_flag = _StopFlag(ctl)
        stop_flag.term = pending_term[0]
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
        watch = PeerWatch(bus["beat"], peers)
        hooks = _CycleHooks(bus, ft, spec.ages.ft, inputs, watch)
        sources = Sources(
            ft=None if ft is None else ft.buffer, tactile=inputs.get("tactile"), instruments=inputs.get("instruments")
        )
        loop = ControlLoop(
            robot,
            ctrl,
            sup,
            sources,  # type: ignore[arg-type]
            ages=spec.ages,
            logger=sink,  # type: ignore[arg-type]
            pre_cycle=hooks,
            gc_freeze=spec.rt.gc_freeze,
            stop_timeout=spec.stop_timeout,
        )
        hooks.loop = loop
        extra = spec.loop_hook(loop) if spec.loop_hook is not None else None
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
        bus["beat"][BEAT_CHILD] = now
        ctl[CTL_PHASE] = PHASE_RUNNING
        stats = loop.run(duration, stop_flag)  # type: ignore[arg-type]
        ctl[CTL_PHASE] = PHASE_DONE
        report = hooks.report()
        report.update(log_dropped=bus.ring("log").dropped, events_dropped=bus.ring("events").dropped,
                      encode_errors=sink.encode_errors)
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


# -- the parent side ----------------------------------------------------------------------------------
@dataclass
class RtResult:
    """What the parent gets back: the loop's statistics and the child's report."""

    stats: LoopStats
    report: dict[str, Any]


class RtProcess:
    """Runs the control loop of ``spec`` in a spawned process and serves it from this one.

    Args:
        spec: What the child builds.
        tactile: The tactile latest-value buffer to feed (``None``: no tactile source).
        logger: A :class:`~lapwrench.hardware.log.RunLogger` (or duck-typed) for cycles and events.
        detector_pid: The detector process the child should watch (its slot is fed by it).
        feeder: Run the parent's feeder thread (tactile slot + parent heartbeat). Tests turn it
            off and feed the bus from another process, whose pid is then ``feeder_pid``.
        feeder_pid: The process whose heartbeat the child watches as its feeder (default: this one).
        child_timeout: Child heartbeat age (s) that counts as a hang.
        connect_timeout: Seconds the child may take from "go" to its first cycle (robot connect).
        feed_period: Feeder period (s).
    """

    def __init__(
        self,
        spec: RtSpec,
        *,
        tactile: LatestValue[Any] | None = None,
        logger: Any = None,
        detector_pid: int | None = None,
        feeder: bool = True,
        feeder_pid: int | None = None,
        child_timeout: float = 0.5,
        connect_timeout: float = 60.0,
        feed_period: float = 0.001,
        start_method: str = "spawn",
    ) -> None:
        if start_method not in ("spawn", "forkserver"):
            raise ValueError("the real-time process is started with 'spawn' or 'forkserver', never 'fork'")
        self.spec = spec
        self.tactile = tactile
        self.logger = logger
        self.detector_pid = detector_pid
        self.feeder = feeder
        self.feeder_pid = os.getpid() if feeder_pid is None else feeder_pid
        self.child_timeout = child_timeout
        self.connect_timeout = connect_timeout
        self.feed_period = feed_period
        self.ctx = mp.get_context(start_method)
        self.bus = Bus.create(bus_layout(spec.log_rows, spec.event_rows))
        self.codec = CycleCodec()
        self.proc: Any = None
        self.ready: dict[str, Any] = {}
        self.events: list[tuple[float, str, str]] = []
        self.cycles_logged = 0
        self._conn: Any = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._drain_lock = threading.Lock()

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
        self._conn = parent_conn
        self.proc = self.ctx.Process(
            target=_child_main,
            args=(self.spec, self.bus.name, child_conn, self.peers()),
            name="lapwrench-rt",
            daemon=True,
        )
        self.bus["beat"][BEAT_PARENT] = time.monotonic()
        self.proc.start()
        child_conn.close()
        self._start_threads()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if parent_conn.poll(0.05):
                msg = self._recv()
                if msg[0] == "ready":
                    self.ready = msg[1]
                    return self.ready
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

        ``stop_event.is_set()`` requests the child's clean stop to rest (Ctrl-C in the CLI).

        Raises:
            RtProcessError: the child died, hung, or reported a robot/device/internal error.
        """
        if self.proc is None:
            self.start()
        self._t_go = time.monotonic()
        self._conn.send(("go", script_t0, self.spec.duration if duration is None else duration))
        ctl, beat = self.bus["ctl"], self.bus["beat"]
        stop_sent = False
        try:
            while True:
                if stop_event is not None and not stop_sent and stop_event.is_set():
                    ctl[CTL_STOP] = 1
                    stop_sent = True
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
        """Stop the child (stop request, then SIGTERM, then SIGKILL), the threads, and free the bus."""
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


def _error(kind: str, message: str) -> RtProcessError:
    e = RtProcessError(message)
    e.kind = kind  # type: ignore[attr-defined]
    return e


# -- robot factories (module level: picklable for the spawned child) ---------------------------------
def franka_factory(
    cfg: Any,
    script: Any,
    *,
    robot_ip: str,
    kind: str,
    realtime: str = "enforce",
    ext_wrench_sign: str = "robot_on_environment",
    report_external_force: bool = True,
    payload: bool = True,
) -> Any:
    """A :class:`~lapwrench.hardware.franka.FrankaRobot` (use with ``functools.partial``)."""
    from lapwrench.hardware.franka import FrankaRobot, Payload
    from lapwrench.robot.description import ScopeGeometry

    return FrankaRobot(
        robot_ip,
        kind=kind,  # type: ignore[arg-type]
        realtime=realtime,  # type: ignore[arg-type]
        ext_wrench_sign=ext_wrench_sign,  # type: ignore[arg-type]
        report_external_force=report_external_force,
        load=Payload.from_scope(ScopeGeometry.from_config(cfg.scope)) if payload else None,
        dt=cfg.robot.dt,
    )


def _script_force(script: Any, _t: float) -> np.ndarray:
    return script.force_H()


def sim_factory(cfg: Any, script: Any, *, realtime: bool = True, q0: Any = None) -> Any:
    """A :class:`~lapwrench.sim.robot.SimRobot` on the configured scene; a dry-run ``script``'s hand
    force is applied to the handle (on the script's clock, shared with the parent)."""
    from lapwrench.sim.robot import SimRobot
    from lapwrench.sim.scene import SceneConfig
    from lapwrench.sim.world import SimWorld

    world = SimWorld(SceneConfig.from_config(cfg))
    hand = None if script is None else _bind(_script_force, script)
    return SimRobot(world, q0=q0, realtime=realtime, hand_force_H=hand)


def _bind(f: Callable[..., Any], *args: Any) -> Callable[..., Any]:
    import functools

    return functools.partial(f, *args)
