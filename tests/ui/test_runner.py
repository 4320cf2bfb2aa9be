"""The sim thread's pacing, driven by a hand-moved clock (no wall-clock assertions)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable

import pytest

from lapwrench.ui.runner import MAX_LAG, RealTimeRunner, raise_priority, real_time_priority


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


def test_a_dropped_backlog_is_counted_and_reported_once_by_kept_up(
    setup: tuple[RealTimeRunner, FakeSim, Clock],
) -> None:
    runner, _sim, clock = setup
    assert runner.kept_up() and runner.dropped == 0.0
    clock.now += 1.0  # a stall far beyond max_lag (0.05 s here)
    assert eventually(lambda: runner.dropped > 0.0)
    assert runner.dropped == pytest.approx(1.0, abs=0.01)
    assert not runner.kept_up()  # since the last call, time was lost
    assert runner.kept_up()  # and nothing since


def test_a_stall_shorter_than_the_default_max_lag_is_caught_up() -> None:
    sim, clock = FakeSim(), Clock()
    runner = RealTimeRunner(sim.step, lambda: sim.t, window=0.01, clock=clock)
    assert runner.max_lag == MAX_LAG >= 0.2
    runner.start()
    try:
        clock.now += 0.2  # the thread stalled for 0.2 s (a busy machine)
        assert eventually(lambda: sim.t >= 0.1995)
        time.sleep(0.05)
        assert sim.t == pytest.approx(0.2, abs=0.0015)  # every tick stepped: real time kept
        assert runner.dropped == 0.0 and runner.kept_up()
    finally:
        runner.stop()


def test_raise_priority_only_ever_raises_a_threads_priority() -> None:
    out: dict[str, int] = {}

    def probe() -> None:  # in a thread of its own: niceness is per thread, this one ends with the test
        tid = threading.get_native_id()
        out["before"] = os.getpriority(os.PRIO_PROCESS, tid)
        out["higher_nice"] = raise_priority(out["before"] + 5)  # a lower priority is never taken
        out["lower_nice"] = raise_priority(out["before"] - 1)  # granted where permitted
        out["after"] = os.getpriority(os.PRIO_PROCESS, tid)

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    assert out["higher_nice"] == out["before"]
    assert out["lower_nice"] in (out["before"], out["before"] - 1)
    assert out["after"] == out["lower_nice"]


def test_real_time_priority_is_granted_or_the_thread_is_left_as_it_was() -> None:
    out: dict[str, object] = {}

    def probe() -> None:  # in a thread of its own: the policy is per thread, this one ends with the test
        out["granted"] = real_time_priority(1)
        out["policy"] = os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK
        out["priority"] = os.sched_getparam(0).sched_priority

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    if out["granted"]:
        assert out["policy"] == os.SCHED_RR and out["priority"] == 1
    else:
        assert out["policy"] == os.SCHED_OTHER and out["priority"] == 0
