"""The hardware side of the one control loop (:class:`lapwrench.loop.ControlLoop`).

Every sensor source (F/T, tactile, camera, the instrument detector) runs its own thread or process
and publishes into a :class:`~lapwrench.buffer.LatestValue` (or a shared-memory slot of
the same shape). The loop only *peeks*: each cycle it takes the newest sample of each buffer if it
is at most its ``max_age`` old (:class:`SourceAges`), otherwise ``None`` — and a ``None`` input
switches that source's wrench off in the controller. Nothing in the loop waits on a sensor, a
camera, a detector or the log file (:class:`~lapwrench.hardware.log.RunLogger` writes from its
own thread, or from the parent process: :mod:`lapwrench.hardware.rt`).

:class:`ControlLoop` here is the one loop with its hardware wiring: the buffers become
:class:`~lapwrench.sources.BufferSource` s, the clock is ``time.monotonic()`` (the clock the
drivers stamp with; the robot's own time is logged beside it), every cycle's compute time is
checked against the supervisor's deadline, and each cycle is logged. It works unchanged with
:class:`~lapwrench.hardware.franka.FrankaRobot` and :class:`~lapwrench.sim.robot.SimRobot`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lapwrench import loop
from lapwrench.buffer import LatestValue, SampleBuffer
from lapwrench.controller import Controller
from lapwrench.hardware.log import RunLogger
from lapwrench.hardware.log.record import cycle_record
from lapwrench.loop_stats import Cycle, LoopStats
from lapwrench.robot_interface import RobotInterface
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorEvent
from lapwrench.sensors import InstrumentObservation
from lapwrench.sources import (
    BufferSource,
    Source,
    ft_reading,
    instruments_reading,
    registered_reading,
    tactile_reading,
)
from lapwrench.spatial import Vec

__all__ = ["ControlLoop", "DetectorWorker", "LoopStats", "SourceAges", "Sources", "hardware_sources"]


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
    timestamp is used). ``None``: no such source. ``extra``: the registered inputs the cues ask for
    (:mod:`lapwrench.inputs`), each a buffer of arrays and its maximum age.
    """

    ft: SampleBuffer[Any] | None = None
    tactile: SampleBuffer[Any] | None = None
    instruments: SampleBuffer[InstrumentObservation] | None = None
    extra: dict[str, tuple[Any, float]] = field(default_factory=dict)  # registered inputs: (buffer, max age s)


def hardware_sources(sources: Sources, ages: SourceAges) -> list[Source]:
    """The loop's :class:`~lapwrench.sources.Source` s for these buffers and maximum ages."""
    out: list[Source] = []
    if sources.ft is not None:
        out.append(BufferSource("ft", sources.ft, ft_reading, max_age=ages.ft))
    if sources.tactile is not None:
        out.append(BufferSource("tactile", sources.tactile, tactile_reading, max_age=ages.tactile))
    if sources.instruments is not None:
        out.append(BufferSource("instruments", sources.instruments, instruments_reading, max_age=ages.instruments))
    for name, (buffer, max_age) in sources.extra.items():
        out.append(BufferSource(name, buffer, registered_reading, max_age=max_age))
    return out


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


class ControlLoop(loop.ControlLoop):
    """The one control loop on hardware buffers, with wall-clock deadlines and the MCAP logger.

    Args:
        robot: A :class:`~lapwrench.robot_interface.RobotInterface` (Franka or simulation).
        controller: The controller (reset by :meth:`start` at the robot's measured pose).
        supervisor: The safety supervisor every command passes through.
        sources: Sensor buffers (:class:`Sources`).
        ages: Maximum sample ages.
        logger: Optional run logger (anything with ``cycle(CycleRecord)`` and ``event(t, kind, msg)``).
        The rest: see :class:`lapwrench.loop.ControlLoop`.
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
        after_command: Callable[[float], None] | None = None,
        gc_freeze: bool = False,
    ) -> None:
        self.ages = ages or SourceAges()
        self.logger = logger
        super().__init__(
            robot, controller, supervisor, (), clock=time.monotonic, wall_deadlines=True, on_cycle=self._log,
            on_events=self._log_events, command_hook=command_hook, compute_hook=compute_hook,
            pre_cycle=pre_cycle, after_command=after_command, stop_timeout=stop_timeout,
            switch_interval=switch_interval, gc_freeze=gc_freeze,
        )
        self.sources = sources or Sources()

    @property
    def sources(self) -> list[Source]:
        return self._source_list

    @sources.setter
    def sources(self, value: Sources | Sequence[Source]) -> None:
        self._source_list = hardware_sources(value, self.ages) if isinstance(value, Sources) else list(value)
        for s in self._source_list:
            if isinstance(s, BufferSource):
                s.t0 = self.t0

    def _log_events(self, events: list[SupervisorEvent]) -> None:
        if self.logger is not None:
            for e in events:
                self.logger.event(e.time, e.kind, e.message)

    def _log(self, c: Cycle) -> None:
        if self.logger is None:
            return
        if getattr(self.logger, "logs_cycles", True):  # the real-time process's sink: events only without --log
            state = str(self.supervisor.state)  # a StrEnum's value by str's __str__ (Enum's .value is a slow property)
            rec = cycle_record(c, state, self.supervisor.alarm, getattr(self.robot, "tau_J", None))
            if rec is not None:
                self.logger.cycle(rec)
        self._log_events(c.events)

