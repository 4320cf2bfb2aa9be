"""The sim thread: steps the session's 1 ms ticks paced to the wall clock.

The simulated time follows the wall clock: the thread steps until it has caught up, then sleeps
until the next tick is due. A short stall (the thread waiting for a core that the browser or the
view's render process holds) is caught up: a tick takes about half a millisecond, so a backlog of
up to ``max_lag`` is gone within about as long again, and the simulation keeps real time. On a
machine too slow for real time it steps without pause and the simulation runs in slow motion: a
backlog beyond ``max_lag`` is dropped (counted in :attr:`RealTimeRunner.dropped`) rather than
caught up in a long burst (which would make the scope race on the page). The real-time factor
(simulated seconds per wall second over the last ``window``) says how fast it really runs.

On a two-core machine the sim thread shares the cores with the view's render process and the
browser (software WebGL), and each of its thousand wake-ups a second can wait for a core. So it asks,
as ``lapwrench run`` does for its loop, for the lowest real-time priority (SCHED_RR
:data:`SIM_RT_PRIORITY`, on a machine of two cores or more, not passed on to processes it starts),
else for a higher niceness (:data:`SIM_NICE`), each where the system permits it (root,
``RLIMIT_RTPRIO``, ``RLIMIT_NICE``); elsewhere it runs at the default priority
(:attr:`RealTimeRunner.realtime` and :attr:`RealTimeRunner.nice` say which). It sleeps whenever it
has caught up, and a real-time thread that cannot keep up is held to 95 % of one core by Linux.

An exception from a tick (an unstable simulation, a bug) pauses the runner with the message in
:attr:`RealTimeRunner.error` for the page to show; a reset clears it.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable

from lapwrench.sim.world import CONTROL_DT

SIM_RT_PRIORITY = 1  # SCHED_RR priority of the sim thread where permitted: before the browser and the render
SIM_NICE = -5  # the sim thread's niceness where real-time scheduling is not permitted
MAX_LAG = 0.25  # s of backlog caught up after a stall (at twice real time: a quarter second of fast motion)


class RealTimeRunner:
    """Steps ``step()`` (one tick of ``dt`` simulated seconds) at wall-clock pace on its own thread.

    Args:
        step: One tick (the session's :meth:`~lapwrench.ui.session.Session.step`).
        sim_time: The simulated time (s) after the last tick.
        dt: Simulated seconds per tick.
        max_lag: Largest backlog (s) the runner catches up; beyond it the backlog is dropped.
            (:data:`MAX_LAG`: long enough for the stalls of a busy two-core machine.)
        window: Wall seconds over which the real-time factor is measured.
        clock: Wall clock (s).
    """

    def __init__(self, step: Callable[[], object], sim_time: Callable[[], float], *, dt: float = CONTROL_DT,
                 max_lag: float = MAX_LAG, window: float = 0.5, clock: Callable[[], float] = time.perf_counter) -> None:
        self.step = step
        self.sim_time = sim_time
        self.dt = dt
        self.max_lag = max_lag
        self.window = window
        self.clock = clock
        self.paused = False
        self.error: str | None = None
        self.rtf = float("nan")  # simulated / wall seconds over the last window; NaN while paused
        self.ticks = 0
        self.step_seconds = 0.0  # wall time of the ticks in the last window, per tick
        self.dropped = 0.0  # simulated seconds of backlog dropped since the start (time not kept up with)
        self._dropped_seen = 0.0  # self.dropped at the last kept_up()
        self.nice: int | None = None  # the sim thread's niceness once it runs
        self.realtime = False  # whether the sim thread runs at real-time priority (SCHED_RR)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- life cycle ---------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("runner already started")
        self._thread = threading.Thread(target=self._run, name="lapwrench-ui-sim", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def kept_up(self) -> bool:
        """Whether the simulation kept real time since the last call: no backlog was dropped (a stall
        that was caught up does not count)."""
        seen, self._dropped_seen = self._dropped_seen, self.dropped
        return self._dropped_seen == seen

    def clear_error(self) -> None:
        """Clear a tick's error (after a reset) and run again."""
        self.error = None
        self.paused = False

    # -- the loop -----------------------------------------------------------------------------
    def _run(self) -> None:
        self.realtime = real_time_priority(SIM_RT_PRIORITY)
        self.nice = raise_priority(SIM_NICE)
        anchor_wall, anchor_sim = self.clock(), self.sim_time()
        win_wall, win_sim, win_ticks, win_busy = anchor_wall, anchor_sim, 0, 0.0
        while not self._stop.is_set():
            now = self.clock()
            if self.paused or self.error is not None:
                self.rtf = float("nan")
                time.sleep(0.02)
                anchor_wall, anchor_sim = self.clock(), self.sim_time()
                win_wall, win_sim, win_ticks, win_busy = anchor_wall, anchor_sim, 0, 0.0
                continue
            sim = self.sim_time()
            if sim < anchor_sim:  # the session was reset: its time restarted
                anchor_wall, anchor_sim, win_wall, win_sim = now, sim, now, sim
            behind = anchor_sim + (now - anchor_wall) - sim
            if behind > self.max_lag:  # too slow for real time: drop the backlog
                self.dropped += behind
                anchor_wall, anchor_sim = now, sim
                behind = 0.0
            if behind >= 0.5 * self.dt:
                t0 = self.clock()
                try:
                    self.step()
                except Exception as exc:  # shown on the page; a reset recovers
                    self.error = f"simulation stopped: {type(exc).__name__}: {exc}"
                    continue
                win_busy += self.clock() - t0
                win_ticks += 1
                self.ticks += 1
            else:
                time.sleep(max(0.0, self.dt - behind))
            if now - win_wall >= self.window:
                self.rtf = (self.sim_time() - win_sim) / (now - win_wall)
                self.step_seconds = win_busy / max(win_ticks, 1)
                win_wall, win_sim, win_ticks, win_busy = now, self.sim_time(), 0, 0.0


def raise_priority(nice: int) -> int:
    """Give the calling thread niceness ``nice`` if the system permits it (a lower niceness needs
    root or ``RLIMIT_NICE``) and it is higher than the thread's; return the niceness it has."""
    tid = threading.get_native_id()
    with contextlib.suppress(OSError):
        if nice < os.getpriority(os.PRIO_PROCESS, tid):
            os.setpriority(os.PRIO_PROCESS, tid, nice)
    return os.getpriority(os.PRIO_PROCESS, tid)


def real_time_priority(priority: int) -> bool:
    """Put the calling thread in SCHED_RR at ``priority`` (not passed on to children), if the system
    permits it and has two cores or more (one is left to the rest); returns whether it is."""
    if (os.cpu_count() or 1) < 2 or not hasattr(os, "SCHED_RR"):
        return False
    with contextlib.suppress(OSError):
        os.sched_setscheduler(0, os.SCHED_RR | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    return os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK == os.SCHED_RR
