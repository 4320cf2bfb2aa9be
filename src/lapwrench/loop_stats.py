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
    """What a run measured. Times in microseconds; ``cycle_us`` is the period between reads."""

    cycles: int = 0
    cycle_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    compute_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_measured: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rcm_error_reference: np.ndarray = field(default_factory=lambda: np.zeros(0))
    commands: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # cycles x joints
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
            "rcm_error_measured_max_mm": round(float(self.rcm_error_measured.max()) * 1e3, 4)
            if self.rcm_error_measured.size
            else None,
            "alarm": self.alarm,
            "stopped_at_rest": self.stopped_at_rest,
        }


class Growable:
    """Append-only float array without per-append allocation."""

    def __init__(self, width: int = 0, capacity: int = 16384) -> None:
        self.n = 0
        self.a = np.zeros((capacity, width) if width else capacity)

    def append(self, x: Any) -> None:
        if self.n == self.a.shape[0]:
            self.a = np.concatenate([self.a, np.zeros_like(self.a)])
        self.a[self.n] = x
        self.n += 1

    def array(self) -> np.ndarray:
        return self.a[: self.n].copy()


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

