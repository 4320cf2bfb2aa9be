"""The sim thread: steps the session's 1 ms ticks paced to the wall clock.

The simulated time follows the wall clock: the thread steps until it has caught up, then sleeps
until the next tick is due. On a machine too slow for real time it steps without pause and the
simulation runs in slow motion: a backlog beyond ``max_lag`` is dropped rather than caught up in a
burst (which would make the scope jump on the page). The real-time factor (simulated seconds per
wall second over the last ``window``) says how fast it really runs.

An exception from a tick (an unstable simulation, a bug) pauses the runner with the message in
:attr:`RealTimeRunner.error` for the page to show; a reset clears it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from lapwrench.sim.world import CONTROL_DT


class RealTimeRunner:
    """Steps ``step()`` (one tick of ``dt`` simulated seconds) at wall-clock pace on its own thread.

    Args:
        step: One tick (the session's :meth:`~lapwrench.ui.session.Session.step`).
        sim_time: The simulated time (s) after the last tick.
        dt: Simulated seconds per tick.
        max_lag: Largest backlog (s) the runner catches up; beyond it the backlog is dropped.
        window: Wall seconds over which the real-time factor is measured.
        clock: Wall clock (s).
    """

    def __init__(self, step: Callable[[], object], sim_time: Callable[[], float], *, dt: float = CONTROL_DT,
                 max_lag: float = 0.05, window: float = 0.5, clock: Callable[[], float] = time.perf_counter) -> None:
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

    def clear_error(self) -> None:
        """Clear a tick's error (after a reset) and run again."""
        self.error = None
        self.paused = False

    # -- the loop -----------------------------------------------------------------------------
    def _run(self) -> None:
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
