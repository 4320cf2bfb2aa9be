"""ControlLoop's thread hygiene (sensor threads keep running while the loop blocks in read()) and
stale sources that never make it wait."""

from __future__ import annotations

import ctypes
import sys
import threading
import time
from typing import Any

import numpy as np
import pytest
from hardware.support import MemoryLogger, build_loop

from lapwrench.buffer import LatestValue
from lapwrench.config import Config
from lapwrench.drivers.ft import Wrench
from lapwrench.hardware.runner import Sources
from lapwrench.sim.robot import SimRobot

# libc's usleep called through PyDLL keeps the GIL, as pylibfranka's readOnce does while it waits
_usleep_holding_gil = ctypes.PyDLL(None).usleep
_usleep_holding_gil.argtypes = [ctypes.c_uint]


class GilHoldingRobot:
    """A simulated robot whose ``read`` blocks 0.9 ms without releasing the GIL."""

    def __init__(self, inner: SimRobot) -> None:
        self.inner = inner
        self.kind = inner.kind
        self.dt = inner.dt

    def connect(self) -> Any:
        return self.inner.connect()

    def read(self) -> Any:
        _usleep_holding_gil(900)
        return self.inner.read()

    def command(self, q_ref: np.ndarray) -> None:
        self.inner.command(q_ref)

    def disconnect(self) -> None:
        self.inner.disconnect()


def count_sensor_wakeups(loop: Any, seconds: float) -> tuple[int, int]:
    """Run ``loop`` for ``seconds`` of robot time beside a thread that sleeps 1 ms per wake-up."""
    wakeups = [0]
    stop = threading.Event()

    def sensor() -> None:
        while not stop.wait(0.001):
            wakeups[0] += 1

    thread = threading.Thread(target=sensor, daemon=True)
    thread.start()
    try:
        stats = loop.run(seconds)
    finally:
        stop.set()
        thread.join(1.0)
    return wakeups[0], stats.cycles


def test_sensor_threads_run_while_read_holds_the_gil(sim_world: Any, panda_cfg: Config) -> None:
    loop, _ = build_loop(GilHoldingRobot(SimRobot(sim_world)), panda_cfg, None)
    wakeups, cycles = count_sensor_wakeups(loop, 1.0)
    # measured: about once per cycle (1002 in 1001); with Python's default 5 ms switch interval
    # and no yield before read(), about once per two cycles (524 in 1001)
    assert wakeups >= 0.75 * cycles, f"{wakeups} sensor wake-ups in {cycles} cycles"


def test_switch_interval_is_set_during_the_run_and_restored(sim_world: Any, panda_cfg: Config) -> None:
    before = sys.getswitchinterval()
    seen: list[float] = []
    loop, _ = build_loop(
        SimRobot(sim_world),
        panda_cfg,
        None,
        switch_interval=2e-4,
        compute_hook=lambda k: seen.append(sys.getswitchinterval()),
    )
    loop.run(0.01)
    assert seen and all(s == pytest.approx(2e-4) for s in seen)
    assert sys.getswitchinterval() == before


@pytest.mark.parametrize("bad", [0.0, -1e-4, float("nan"), float("inf")])
def test_bad_switch_interval_is_refused(bad: float, sim_world: Any, panda_cfg: Config) -> None:
    with pytest.raises(ValueError, match="switch_interval"):
        build_loop(SimRobot(sim_world), panda_cfg, None, switch_interval=bad)


def test_runner_with_stale_sources_never_waits(sim_world: Any, panda_cfg: Any) -> None:
    ft: LatestValue[Any] = LatestValue("ft")
    ft.put(Wrench(np.array([5.0, 0, 0]), np.zeros(3)), time.monotonic() - 10.0)  # long stale
    tactile: LatestValue[Any] = LatestValue("tactile")  # never published
    loop, log = build_loop(SimRobot(sim_world), panda_cfg, None)
    loop.sources = Sources(ft=ft, tactile=tactile)
    stats = loop.run(0.5)
    assert stats.cycles >= 500 and stats.alarm is None
    assert all(c.ft_force is None and c.tactile is None for c in log.cycles)
    stale = [m for _, k, m in log.events if k == "input_stale"]
    assert any(m.startswith("ft") for m in stale) and any(m.startswith("tactile") for m in stale)
    assert np.percentile(stats.compute_us, 50) < 5000


class EventsOnlyLogger(MemoryLogger):
    """A logger that takes events only (the real-time process's sink without ``--log``)."""

    logs_cycles = False


def test_a_logger_that_takes_events_only_is_given_no_cycle_records(sim_world: Any, panda_cfg: Config) -> None:
    loop, _ = build_loop(SimRobot(sim_world), panda_cfg, None)
    log = EventsOnlyLogger()
    loop.logger = log
    loop.sources = Sources(ft=LatestValue("ft"))  # never published: an input_stale event
    stats = loop.run(0.05)
    assert stats.cycles >= 50 and log.cycles == []
    assert any(kind == "input_stale" for _, kind, _ in log.events)
