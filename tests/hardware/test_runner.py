"""ControlLoop's thread hygiene: the sensor threads keep running while the loop blocks in read()."""

from __future__ import annotations

import ctypes
import sys
import threading
from typing import Any

import numpy as np
import pytest
from hardware.support import build_loop

from lapwrench.config import Config
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
