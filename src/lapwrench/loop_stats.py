"""The records of the control loop (:mod:`lapwrench.loop`): what one cycle did and what a run measured.

:class:`Cycle` is one cycle's outcome, handed to the loop's ``on_cycle`` callback (logging,
recording); :class:`LoopStats` is a whole run's figures (cycle period and compute time in
microseconds, measured and reference RCM error, the commands sent, deadline misses and cycles over
the compute budget, the alarm and whether the stop reached rest); :class:`Growable` collects a
run's per-cycle series without allocating at every cycle. Kept apart from the loop so the loop
module holds only what runs a cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np

from lapwrench.controller import TickResult
from lapwrench.safety.supervisor import MeasuredScope, SupervisorEvent
from lapwrench.sensors import RobotReading, SensorFrame
from lapwrench.spatial import Vec


@dataclass
class LoopStats:
    """What a run measured. Times in microseconds; ``cycle_us`` is the period between reads.

    The series (``cycle_us``, ``compute_us``, the RCM errors, ``commands``) and the percentiles taken of
    them cover the run's last 2**20 cycles at most (17.5 minutes at 1 kHz, :class:`Growable`); the counts,
    ``rcm_error_measured_max`` and the alarm cover the whole run.
    """

    cycles: int = 0
    cycle_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    compute_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_measured: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_reference: np.ndarray = field(default_factory=lambda: np.zeros(0))
    commands: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # cycles x joints
    rcm_error_measured_max: float | None = None  # m, over the whole run (None: not given, the series' max)
    q_start: np.ndarray = field(default_factory=lambda: np.zeros(0))  # one value per joint
    p_R: np.ndarray = field(default_factory=lambda: np.zeros(3))
    robot_time: float = 0.0
    wall_time: float = 0.0
    deadline_misses: int = 0
    over_budget: int = 0  # cycles whose compute time exceeded the budget (counted with or without deadlines)
    alarm: str | None = None
    stopped_at_rest: bool = False

    def percentile(self, what: Literal["cycle", "compute"], p: float) -> float:
        a = self.cycle_us if what == "cycle" else self.compute_us
        return float(np.percentile(a, p)) if a.size else float("nan")

    def _rcm_peak(self) -> float | None:
        if self.rcm_error_measured_max is not None:
            return self.rcm_error_measured_max
        return float(self.rcm_error_measured.max()) if self.rcm_error_measured.size else None

    def summary(self) -> dict[str, float | int | str | bool | None]:
        """The run's figures with units in the key names (for the CLI, the reports and the benchmarks)."""
        return {
            "robot_time_s": round(self.robot_time, 3),
            "wall_time_s": round(self.wall_time, 3),
            "cycles": self.cycles,
            "cycle_p50_us": round(self.percentile("cycle", 50), 1),
            "cycle_p99_us": round(self.percentile("cycle", 99), 1),
            "compute_p50_us": round(self.percentile("compute", 50), 1),
            "compute_p99_us": round(self.percentile("compute", 99), 1),
            "deadline_misses": self.deadline_misses,
            "over_budget_cycles": self.over_budget,
            "rcm_error_measured_max_mm": None if (peak := self._rcm_peak()) is None else round(peak * 1e3, 4),
            "alarm": self.alarm,
            "stopped_at_rest": self.stopped_at_rest,
        }


class Growable:
    """An append-only float series for the 1 kHz loop: fixed-size chunks, a new one every ``chunk``
    appends and never a copy of the old ones (a series that doubled its array would stall the loop for
    tens of milliseconds a few minutes into a run, and a Franka aborts after about 20 missed cycles).
    At most the last ``keep`` rows are kept (memory stays bounded in an hours-long run); :attr:`n`
    counts every append, :attr:`dropped` those no longer kept."""

    def __init__(self, width: int = 0, chunk: int = 16384, keep: int = 2**20) -> None:
        if chunk < 1 or keep < 1:
            raise ValueError(f"chunk and keep must be >= 1, got {chunk} and {keep}")
        self.width = width
        self.chunk = chunk
        self.max_chunks = -(-keep // chunk) + 1  # the chunk being filled, and enough full ones for ``keep``
        self.keep = keep
        self.n = 0
        self._chunks: list[np.ndarray] = [self._new()]
        self._filled = 0  # rows in the last chunk

    def _new(self) -> np.ndarray:
        # empty, not zeros: every row is written before it is read, and zeros can memset the whole chunk in the
        # loop's slack (about 1 MB: 21 us p50 and 604 us at worst in 200 tries, against 1.4 and 16 us)
        return np.empty((self.chunk, self.width) if self.width else self.chunk)

    def append(self, x: Any) -> None:
        if self._filled == self.chunk:
            self._chunks.append(self._new())
            self._filled = 0
            if len(self._chunks) > self.max_chunks:
                del self._chunks[0]
        self._chunks[-1][self._filled] = x
        self._filled += 1
        self.n += 1

    @property
    def dropped(self) -> int:
        """Appended rows no longer kept (beyond the last ``keep``)."""
        return self.n - min(self.n, self.keep)

    def array(self) -> np.ndarray:
        """The kept rows, oldest first (at most the last ``keep``), as a new array."""
        parts = [*self._chunks[:-1], self._chunks[-1][: self._filled]]
        return np.concatenate(parts)[-self.keep :] if self.n else parts[-1].copy()


class Cycle(NamedTuple):
    """One cycle's outcome: the frame the controller saw, its result (None after a failed tick),
    the measured scope, the command sent, and the compute time (s). A named tuple: one is made every
    control period."""

    k: int
    frame: SensorFrame
    reading: RobotReading
    result: TickResult | None
    scope: MeasuredScope
    q_cmd: Vec
    compute: float
    period: float
    events: list[SupervisorEvent]  # the supervisor's events of this cycle (drained)

