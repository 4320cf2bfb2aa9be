"""Real-time settings of a process: SCHED_FIFO, CPU affinity, the garbage collector."""

from __future__ import annotations

import os
from dataclasses import dataclass


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
