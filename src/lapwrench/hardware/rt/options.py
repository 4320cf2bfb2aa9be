"""Real-time settings of a process: SCHED_FIFO, CPU affinity, locked memory (:func:`lock_memory`), the garbage
collector."""

from __future__ import annotations

import ctypes
import os
import resource
from dataclasses import dataclass

MCL_CURRENT, MCL_FUTURE = 1, 2
"""``mlockall`` flags (Linux, asm-generic/mman-common.h): the pages mapped now, and every page mapped later."""

CAP_IPC_LOCK = 14
"""The capability that lets a process lock memory beyond its RLIMIT_MEMLOCK (linux/capability.h)."""


@dataclass(frozen=True)
class RtOptions:
    """Scheduling of the real-time process.

    Attributes:
        fifo_priority: SCHED_FIFO priority (1-99) for the loop's thread; ``None``: don't ask.
        cpus: CPU ids to pin the real-time process to; ``None``: don't pin.
        lock_memory: Lock the process's memory (:func:`lock_memory`: ``mlockall(MCL_CURRENT | MCL_FUTURE)``),
            as real-time Linux setups do: no page of the loop is paged out (this VM's kernel pages out cold
            pages) and none faults in during a cycle, every page being resident from its mapping on. The
            real-time child locks once it has built everything (the kernels compiled, the devices open),
            just before it reports ready: not :func:`apply_realtime`'s, which runs first.
        gc_freeze: Freeze and disable the cyclic garbage collector during the run.
        warn: Print the one warning when a setting is not permitted (it is logged either way).
    """

    fifo_priority: int | None = 80
    cpus: tuple[int, ...] | None = None
    lock_memory: bool = True
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


def lock_memory() -> str | None:
    """Lock every page of this process, mapped now and later, in memory; a message when not permitted.

    Only where nothing limits it (RLIMIT_MEMLOCK unlimited, or the ``CAP_IPC_LOCK`` capability, as root has):
    under a finite limit, a page the loop maps later (a new chunk of its series) would count against it, and
    past it an allocation fails, a ``MemoryError`` in the middle of a motion. Then nothing is locked."""
    soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if soft != resource.RLIM_INFINITY and not has_capability(CAP_IPC_LOCK):
        return (
            f"memory not locked: RLIMIT_MEMLOCK is {soft // 1024} kB, not unlimited (a later allocation past it would"
            " fail mid-motion); the loop's pages may fault in or be paged out during a cycle. Allow it (e.g."
            " 'memlock unlimited' via /etc/security/limits.d, as the libfranka real-time setup does)"
        )
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            why = os.strerror(ctypes.get_errno())
            return f"memory not locked: mlockall failed ({why}); the loop's pages may fault in during a cycle"
    except (OSError, AttributeError) as exc:  # no libc, or no mlockall (not Linux)
        return f"memory not locked ({type(exc).__name__}: {exc})"
    return None


def has_capability(cap: int) -> bool:
    """The calling process has capability ``cap`` in its effective set (Linux; False elsewhere)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("CapEff:"):
                    return bool(int(line.split()[1], 16) >> cap & 1)
    except (OSError, ValueError):
        pass
    return False
