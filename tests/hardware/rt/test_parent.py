"""lapwrench.hardware.rt.parent: RtProcess, the parent's side of the real-time process.

What it refuses at construction, how it moves the child's events to the logger (drain, set_logger),
and how each way a child can fail ends: never ready (killed after the start-up timeout), killed during
the start-up, gone before the go. Every failure must be an RtProcessError with its kind, the child
reaped and the bus freed. The full runs with a working child are test_rt_process.py's.
"""

from __future__ import annotations

import functools
import os
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from hardware.support import MemoryLogger, rt_process, rt_spec

from lapwrench.buffer import LatestValue
from lapwrench.config import Config
from lapwrench.hardware.rt import (
    BEAT_DETECTOR,
    BEAT_PARENT,
    CTL_STOP,
    RtProcess,
    RtProcessError,
    ShmLogSink,
    bus_layout,
    sim_factory,
)
from lapwrench.hardware.shm import Bus, ShmError


def never_ready(cfg: Any, script: Any) -> Any:
    """A robot factory that never returns (a connect that hangs before the child is ready)."""
    time.sleep(3600.0)


@pytest.fixture
def closing() -> Iterator[list[RtProcess]]:
    """RtProcesses made by a test, closed (child killed and reaped, bus freed) whatever happens."""
    made: list[RtProcess] = []
    yield made
    for rp in made:
        rp.kill()
        rp.close(timeout=5.0)


def bus_exists(rp: RtProcess) -> bool:
    try:
        Bus.attach(rp.bus_name, bus_layout(rp.spec.log_rows, rp.spec.event_rows)).close()
    except ShmError:
        return False
    return True


# -- construction ------------------------------------------------------------------------------------------
def test_fork_is_refused_before_anything_is_made(panda_cfg: Config) -> None:
    with pytest.raises(ValueError, match="never 'fork'"):
        RtProcess(rt_spec(panda_cfg), start_method="fork")


def test_a_registered_input_without_its_driver_buffer_is_refused(panda_cfg: Config) -> None:
    spec = rt_spec(panda_cfg, inputs=(("pedal", (1,), 0.1), ("knob", (2,), 0.1)))
    with pytest.raises(ValueError, match=r"no driver buffer for the registered inputs \['knob'\]"):
        RtProcess(spec, inputs={"pedal": LatestValue("pedal")})


def test_the_peers_the_child_watches(panda_cfg: Config, closing: list[RtProcess]) -> None:
    rp = rt_process(rt_spec(panda_cfg, feeder_timeout=0.7, detector_timeout=1.3))
    closing.append(rp)
    (feeder,) = rp.peers()
    assert (feeder.name, feeder.beat, feeder.timeout, feeder.pid) == ("feeder", BEAT_PARENT, 0.7, os.getpid())
    rp.detector_pid = 4242
    feeder, detector = rp.peers()
    assert (detector.name, detector.beat, detector.timeout, detector.pid) == ("detector", BEAT_DETECTOR, 1.3, 4242)
    assert rp.pid is None  # nothing spawned yet


def test_close_frees_the_bus(panda_cfg: Config) -> None:
    rp = rt_process(rt_spec(panda_cfg))
    assert bus_exists(rp)
    rp.close()
    assert not bus_exists(rp)
    with rt_process(rt_spec(panda_cfg)) as rp2:
        assert bus_exists(rp2)
    assert not bus_exists(rp2)  # the context manager closes it


def test_close_may_be_called_again(panda_cfg: Config) -> None:
    with rt_process(rt_spec(panda_cfg)) as rp:
        rp.close()
    assert not bus_exists(rp)


# -- the child's events and records -------------------------------------------------------------------------
class BrokenLogger(MemoryLogger):
    def event(self, time: float, kind: str, message: str) -> None:
        raise OSError("disk full")


def test_drain_moves_the_childs_events_to_the_logger(panda_cfg: Config, closing: list[RtProcess]) -> None:
    rp = rt_process(rt_spec(panda_cfg))
    closing.append(rp)
    child_side = ShmLogSink(rp.bus.ring("log"), rp.bus.ring("events"))  # what the child writes through
    child_side.event(0.5, "start", "holding at q0")
    assert rp.drain() == 0  # no cycle records, one event
    assert rp.events == [(0.5, "start", "holding at q0")]
    log = MemoryLogger()
    rp.set_logger(log)  # the events so far are written first
    assert log.events == [(0.5, "start", "holding at q0")]
    child_side.event(1.25, "alarm", "peer_hung: feeder")
    rp.drain()
    assert log.events[-1] == (1.25, "alarm", "peer_hung: feeder") and len(rp.events) == 2
    rp.drain()
    assert len(log.events) == 2  # taken once


def test_a_logger_that_fails_does_not_lose_the_events(panda_cfg: Config, closing: list[RtProcess]) -> None:
    rp = rt_process(rt_spec(panda_cfg), logger=BrokenLogger())
    closing.append(rp)
    ShmLogSink(rp.bus.ring("log"), rp.bus.ring("events")).event(2.0, "stop", "end of run")
    rp.drain()  # the logger's error is not the child's problem
    assert rp.events == [(2.0, "stop", "end of run")]


def test_request_stop_sets_the_stop_word(panda_cfg: Config, closing: list[RtProcess]) -> None:
    rp = rt_process(rt_spec(panda_cfg))
    closing.append(rp)
    assert rp.bus["ctl"][CTL_STOP] == 0
    rp.request_stop()
    assert rp.bus["ctl"][CTL_STOP] == 1


# -- a child that fails -------------------------------------------------------------------------------------
def test_a_child_that_never_gets_ready_is_killed_after_the_timeout(panda_cfg: Config,
                                                                  closing: list[RtProcess]) -> None:
    log = MemoryLogger()
    rp = rt_process(rt_spec(panda_cfg, robot_factory=never_ready), logger=log)
    closing.append(rp)
    with pytest.raises(RtProcessError, match="did not get ready within 1 s") as err:
        rp.start(timeout=1.0)
    assert err.value.kind == "internal"  # type: ignore[attr-defined]
    assert rp.proc.exitcode is not None  # killed and reaped


def killed_during_start_up(rp: RtProcess) -> RtProcessError:
    """Start ``rp`` (a child that never gets ready) and SIGKILL the child as soon as it is spawned."""

    def kill_when_spawned() -> None:
        deadline = time.monotonic() + 60.0
        while rp.pid is None and time.monotonic() < deadline:
            time.sleep(0.01)
        if rp.pid is not None:
            os.kill(rp.pid, signal.SIGKILL)

    killer = threading.Thread(target=kill_when_spawned, daemon=True)
    killer.start()
    with pytest.raises(RtProcessError) as err:
        rp.start(timeout=120.0)
    killer.join(5.0)
    return err.value


def test_a_child_killed_during_the_start_up_is_an_error_of_kind_died(panda_cfg: Config,
                                                                     closing: list[RtProcess]) -> None:
    rp = rt_process(rt_spec(panda_cfg, robot_factory=never_ready))
    closing.append(rp)
    err = killed_during_start_up(rp)
    assert err.kind == "died"  # type: ignore[attr-defined]
    rp.proc.join(10.0)
    assert rp.proc.exitcode == -signal.SIGKILL


def test_a_child_killed_during_the_start_up_is_reported_like_one_killed_in_the_run(
    panda_cfg: Config, closing: list[RtProcess]
) -> None:
    log = MemoryLogger()
    rp = rt_process(rt_spec(panda_cfg, robot_factory=never_ready), logger=log)
    closing.append(rp)
    msg = str(killed_during_start_up(rp))
    assert "during start-up" in msg and "SIGKILL" in msg, msg
    assert "rt_process_died" in log.kinds()


def test_a_spec_that_cannot_reach_the_child_is_refused_and_closed_cleanly(panda_cfg: Config) -> None:
    spec = rt_spec(panda_cfg, robot_factory=lambda cfg, script: None)  # a lambda does not pickle
    rp = rt_process(spec)
    try:
        with pytest.raises(RtProcessError, match="could not be started") as info:
            rp.start(timeout=10.0)
        assert info.value.kind == "internal"  # type: ignore[attr-defined]
        assert rp.pid is None  # nothing was started
        rp.close()
    finally:
        if bus_exists(rp):
            Bus.attach(rp.bus_name, bus_layout(rp.spec.log_rows, rp.spec.event_rows)).shm.unlink()
    assert not bus_exists(rp)


@pytest.mark.slow  # a child that builds the controller and gets ready
def test_a_child_gone_before_the_go_is_an_rt_process_error(panda_cfg: Config, closing: list[RtProcess]) -> None:
    spec = rt_spec(panda_cfg, tactile=False, duration=1.0,
                   robot_factory=functools.partial(sim_factory, realtime=False))
    rp = rt_process(spec)
    closing.append(rp)
    rp.start()
    os.kill(rp.pid, signal.SIGTERM)  # the child's stop request while it waits for the go
    rp.proc.join(60.0)
    assert rp.proc.exitcode == 0  # it ended cleanly (a SIGTERM is a stop request there, not a death)
    with pytest.raises(RtProcessError):
        rp.run()
