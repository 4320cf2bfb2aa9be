"""The sim thread's pacing, driven by a hand-moved clock (no wall-clock assertions)."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from lapwrench.ui.runner import RealTimeRunner


class FakeSim:
    def __init__(self, dt: float = 0.001) -> None:
        self.t = 0.0
        self.dt = dt
        self.fail = False

    def step(self) -> None:
        if self.fail:
            raise RuntimeError("boom")
        self.t += self.dt


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def eventually(condition: Callable[[], bool], timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.005)
    return condition()


@pytest.fixture
def setup() -> tuple[RealTimeRunner, FakeSim, Clock]:
    sim, clock = FakeSim(), Clock()
    runner = RealTimeRunner(sim.step, lambda: sim.t, max_lag=0.05, window=0.01, clock=clock)
    runner.start()
    yield runner, sim, clock
    runner.stop()


def test_the_simulated_time_follows_the_clock(setup: tuple[RealTimeRunner, FakeSim, Clock]) -> None:
    _runner, sim, clock = setup
    time.sleep(0.05)
    assert sim.t == pytest.approx(0.0, abs=0.0015)  # a frozen clock: (almost) no ticks
    clock.now += 0.02
    assert eventually(lambda: sim.t >= 0.0195)
    time.sleep(0.05)
    assert sim.t == pytest.approx(0.02, abs=0.0015)  # caught up, and no further


def test_a_backlog_beyond_max_lag_is_dropped(setup: tuple[RealTimeRunner, FakeSim, Clock]) -> None:
    _runner, sim, clock = setup
    clock.now += 10.0  # the machine stalled for 10 s
    time.sleep(0.2)
    assert sim.t < 0.1  # not 10 s of ticks in a burst


def test_pause_stops_the_ticks(setup: tuple[RealTimeRunner, FakeSim, Clock]) -> None:
    runner, sim, clock = setup
    runner.paused = True
    time.sleep(0.05)
    t = sim.t
    clock.now += 0.02
    time.sleep(0.1)
    assert sim.t == t
    runner.paused = False
    time.sleep(0.1)  # the pause's wall time does not count: the runner starts again from now
    clock.now += 0.02
    assert eventually(lambda: sim.t > t + 0.01)


def test_an_error_in_a_tick_pauses_with_the_message_until_cleared(
    setup: tuple[RealTimeRunner, FakeSim, Clock],
) -> None:
    runner, sim, clock = setup
    sim.fail = True
    clock.now += 0.01
    assert eventually(lambda: runner.error is not None)
    assert "boom" in (runner.error or "")
    assert runner.running
    sim.fail = False
    runner.clear_error()
    time.sleep(0.1)
    clock.now += 0.01
    assert eventually(lambda: sim.t > 0.005)
