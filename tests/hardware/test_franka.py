"""The Franka driver's conventions and errors: the command-port probe, force sign, scope payload,
an unreachable robot."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from typing import Any

import numpy as np
import pytest
from hardware.support import FRANKYSIM_MISSING
from helpers import thread_policy

from lapwrench.hardware import franka
from lapwrench.hardware.franka import CollisionThresholds, FrankaRobot, Payload, map_external_force
from lapwrench.robot.description import ScopeGeometry
from lapwrench.robot.errors import RobotError
from lapwrench.robot_interface import RobotInterface


def test_external_force_sign_mapping() -> None:
    # libfranka: forces the robot applies to the environment are positive
    assert np.allclose(map_external_force([1, 2, 3, 9, 9, 9], "robot_on_environment"), [-1, -2, -3])
    assert np.allclose(map_external_force([1, 2, 3, 9, 9, 9], "environment_on_robot"), [1, 2, 3])
    with pytest.raises(ValueError):
        FrankaRobot("127.0.0.1", ext_wrench_sign="up")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        CollisionThresholds(lower_torque=(50.0,) * 7)


def test_scope_payload() -> None:
    p = Payload.from_scope(ScopeGeometry())
    assert p.mass == pytest.approx(0.8)
    assert 0.04 < p.com[2] < 0.145 and p.inertia[0] > 0 and p.inertia[8] > 0


@pytest.mark.skipif(FRANKYSIM_MISSING is not None, reason=f"pylibfranka unusable: {FRANKYSIM_MISSING}")
def test_unreachable_robot_error_names_the_address() -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.bind(("127.0.0.1", 1337))
    except OSError:
        pytest.skip("127.0.0.1:1337 is in use (a franky-sim server is running)")
    finally:
        s.close()
    robot = FrankaRobot("127.0.0.1", kind="fr3", realtime="ignore")
    assert isinstance(robot, RobotInterface)
    with pytest.raises(RobotError, match=r"127\.0\.0\.1"):
        robot.connect()
    with pytest.raises(RobotError, match="not connected"):
        robot.read()


# -- item 12: an unreachable robot is named within seconds ---------------------------------------------
def test_probe_answers_for_a_listening_or_refusing_host() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        assert franka.probe_command_port("127.0.0.1", port, timeout=2.0) is None
    # nothing listens any more: refused, i.e. the host answered (libfranka reports that itself at once)
    assert franka.probe_command_port("127.0.0.1", port, timeout=2.0) is None


def test_probe_names_an_unknown_host() -> None:
    problem = franka.probe_command_port("no-such-robot.invalid", timeout=2.0)
    assert problem is not None and "no-such-robot.invalid" in problem


def test_the_probe_uses_libfrankas_command_port(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, int]] = []

    def connect(address: tuple[str, int], timeout: float) -> Any:
        seen.append(address)
        raise TimeoutError("timed out")

    monkeypatch.setattr(franka.socket, "create_connection", connect)
    assert "no answer" in (franka.probe_command_port("172.16.0.2") or "")
    assert seen == [("172.16.0.2", 1337)] and franka.FRANKA_COMMAND_PORT == 1337


def test_libfrankas_real_time_priority_is_not_passed_on_and_is_given_back(frankysim: Any) -> None:
    """libfranka raises the connecting thread to SCHED_FIFO 99 where permitted. While connected, a
    process or thread started from it runs at the normal policy (a browser or a detector at FIFO 99 would
    starve the machine, the loop included); after disconnect the thread has its own policy back."""
    before = thread_policy()
    robot = FrankaRobot("127.0.0.1", kind="fr3", realtime="ignore", report_external_force=False)
    robot.connect()
    try:
        connected = thread_policy()
        child = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                               capture_output=True, text=True, timeout=60)
        seen: list[tuple[int, int]] = []
        t = threading.Thread(target=lambda: seen.append(thread_policy()))
        t.start()
        t.join()
        robot.read()
    finally:
        robot.disconnect()
    print(f"\nbefore {before}, connected {connected}, after {thread_policy()}")
    assert int(child.stdout) == os.SCHED_OTHER, child
    assert seen == [(os.SCHED_OTHER, 0)]
    assert thread_policy() == before


def test_error_recovery_needs_a_connection() -> None:
    with pytest.raises(RobotError, match="not connected"):
        FrankaRobot("127.0.0.1", kind="fr3").error_recovery()
