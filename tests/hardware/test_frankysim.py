"""lapwrench.hardware.frankysim: the franky-sim server in a process of its own, started and stopped by its pid.

What the controller does against it is test_frankysim_e2e.py's; here the server's own life cycle: it
serves the libfranka command port once ready and writes its step statistics when stopped; a server
that cannot start (bad arguments), or a port another user holds (the lock), ends in a
:class:`FrankySimError` naming why, with nothing left running.
"""

from __future__ import annotations

import fcntl
import os
import socket
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hardware.support import FRANKYSIM_MISSING

from lapwrench.hardware.frankysim import (
    COMMAND_PORT,
    LOOPBACK,
    FrankySimError,
    FrankySimServer,
    StepStats,
    frankysim_available,
    main,
)

LOCK = Path(tempfile.gettempdir()) / f"lapwrench-frankysim-{COMMAND_PORT}.lock"


def test_step_stats_realtime_factor() -> None:
    assert StepStats(steps=2000, p50_us=10.0, p99_us=20.0, max_us=30.0, wall_s=4.0).realtime_factor == 0.5
    assert StepStats(steps=2000, p50_us=10.0, p99_us=20.0, max_us=30.0, wall_s=0.0).realtime_factor == 0.0


@pytest.mark.parametrize("module", ["pylibfranka", "franky_sim"])
def test_frankysim_available_names_what_is_missing(module: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, module, None)  # as if it were not installed
    missing = frankysim_available()
    assert missing is not None and missing.startswith("ModuleNotFoundError: ") and module in missing


@pytest.mark.parametrize("q0", ["1,2", "0,0,0,0,0,0,0,0"])
def test_the_server_refuses_a_q0_of_the_wrong_length(q0: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--q0", q0])
    assert info.value.code == 2 and "--q0 needs 7 values" in capsys.readouterr().err


@pytest.mark.parametrize("q0", ["a,0,0,0,0,0,0", "", "nan,0,0,0,0,0,0", "0,0,0,inf,0,0,0"])
def test_the_server_refuses_a_q0_that_is_not_numbers(q0: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--q0", q0])
    assert info.value.code == 2 and "--q0 needs" in capsys.readouterr().err


@pytest.fixture
def held_lock() -> Iterator[None]:
    """The franky-sim lock, held as another user of the machine would hold it."""
    f = LOCK.open("a+")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        pytest.skip("another franky-sim user holds the lock now")
    try:
        yield
    finally:
        fcntl.flock(f, fcntl.LOCK_UN)
        f.close()


def test_a_server_waits_for_the_lock_then_gives_up_with_a_clear_error(held_lock: None) -> None:
    server = FrankySimServer(lock_timeout=0.3)
    with pytest.raises(FrankySimError, match="another franky-sim user holds"):
        server.start()
    assert server.pid is None and not server.running  # nothing was started


def start_or_skip(server: FrankySimServer) -> None:
    """``server.start()``; a skip when another user of this machine has the lock or the port."""
    try:
        server.start()
    except FrankySimError as exc:
        if "another franky-sim user" in str(exc) or "is in use" in str(exc):
            pytest.skip(str(exc))
        raise


def test_a_server_that_exits_at_once_is_an_error_with_its_output() -> None:
    """A wrong initial configuration (3 joints for the 7 of an FR3): the server's own usage error is shown."""
    server = FrankySimServer(np.zeros(3), lock_timeout=20.0, start_timeout=60.0)
    with pytest.raises(FrankySimError) as err:
        start_or_skip(server)
    assert "exited with code 2" in str(err.value) and "--q0 needs 7 values" in str(err.value)
    assert not server.running and server.stats is None  # stopped, no statistics from a server that never ran
    server.stop()  # stopping again is harmless


def port_accepts(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=5.0):
            return True
    except OSError:
        return False


@pytest.mark.slow  # starts franky-sim (MuJoCo) in a process of its own
@pytest.mark.skipif(FRANKYSIM_MISSING is not None, reason=f"franky-sim unavailable: {FRANKYSIM_MISSING}")
def test_the_server_serves_the_command_port_and_reports_its_steps_when_stopped() -> None:
    server = FrankySimServer(np.zeros(7), realtime=False, lock_timeout=20.0)
    start_or_skip(server)
    try:
        assert server.running and server.pid is not None and server.pid != os.getpid()
        assert port_accepts(LOOPBACK, COMMAND_PORT)  # what pylibfranka connects to
        pid = server.pid
    finally:
        server.stop()
    assert not server.running
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # stopped and reaped by its pid
    stats = server.stats
    assert stats is not None and stats.steps > 0 and stats.wall_s > 0.0
    assert 0.0 < stats.p50_us <= stats.p99_us <= stats.max_us and stats.realtime_factor > 0.0
    server.stop()  # stopping again is harmless
