"""Helpers shared by the tests."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lapwrench.robot.model import Kinematics, RobotModel

if TYPE_CHECKING:
    from lapwrench.robot.limits import JointLimits
    from lapwrench.sim.scene.build import Scene
    from lapwrench.sim.world import SimWorld


def random_configuration(model: RobotModel, rng: np.random.Generator) -> np.ndarray:
    lo, hi = model.limits.position_lower, model.limits.position_upper
    return lo + (hi - lo) * (0.1 + 0.8 * rng.random(7))


def make_renderable_world(scene: Scene | None = None) -> SimWorld:
    """A world (default scene unless given) whose renderer works, or a pytest skip naming why
    EGL is unusable. Set ``MUJOCO_GL`` before the first mujoco import (the conftests do)."""
    from lapwrench.sim.world import SimWorld

    w = SimWorld(scene)
    try:
        w.render()
    except Exception as exc:  # GL context creation fails without EGL/Mesa
        w.close()
        pytest.skip(f"headless rendering unavailable (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}")
    return w


FT_RATE_HZ = 400.0  # the simulated F/T box's record rate: modest, for 2 slow CI cores


def wait_until(cond: Callable[[], bool], timeout: float = 3.0, step: float = 0.005) -> bool:
    """Poll ``cond`` until it holds or ``timeout`` seconds pass; its last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step)
    return cond()


def open_fds() -> set[str]:
    """This process's open file descriptors (Linux): shows a driver's socket or file come and go."""
    return set(os.listdir("/proc/self/fd"))


FD_STEP = 1e-6


def numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], q: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    """Central finite differences of ``f`` at ``q``, one column per component of ``q``."""
    cols = []
    for i in range(q.size):
        dq = np.zeros_like(q)
        dq[i] = h
        cols.append((f(q + dq) - f(q - dq)) / (2 * h))
    return np.stack(cols, axis=1)


def kinematics_at_rest(model: RobotModel, q: np.ndarray) -> Kinematics:
    """The model's kinematics at ``q`` with zero joint velocity."""
    return model.kinematics(q, np.zeros(model.nv))


def two_joint_limits() -> JointLimits:
    """A made-up two-joint arm's limits (no robot description needed): parameters that follow the
    arm's joint count."""
    from lapwrench.robot.limits import JointLimits

    return JointLimits(
        position_lower=np.array([-1.0, -2.0]),
        position_upper=np.array([1.0, 2.0]),
        velocity=np.array([2.0, 4.0]),
        acceleration=np.array([10.0, 20.0]),
        jerk=np.array([1000.0, 2000.0]),
        torque=np.array([80.0, 12.0]),
        torque_rate=np.array([1000.0, 1000.0]),
    )


def write_file(folder: Path, text: str | bytes, name: str = "c.yaml") -> Path:
    """``text`` (or bytes, written as they are) in ``folder/name``; returns the path."""
    path = folder / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def unaligned(values: np.ndarray) -> np.ndarray:
    """A float64 array with the values of ``values`` in memory that is not 8-byte aligned."""
    raw = bytearray(values.nbytes + 1)
    a = np.frombuffer(raw, dtype=np.float64, count=values.size, offset=1).reshape(values.shape)
    a[...] = values
    assert not a.flags.aligned
    return a


def thread_policy(tid: int = 0) -> tuple[int, int]:
    """A thread's scheduling policy (without SCHED_RESET_ON_FORK) and priority; ``tid`` 0: the calling thread."""
    if not hasattr(os, "sched_getscheduler"):
        return (0, 0)
    return os.sched_getscheduler(tid) & ~os.SCHED_RESET_ON_FORK, os.sched_getparam(tid).sched_priority


@contextlib.contextmanager
def kernel_arrival_stamps(timeout: float = 5.0) -> Iterator[None]:
    """While the block runs, Linux stamps every datagram as it arrives (``SO_TIMESTAMPNS``).

    The kernel switches arrival stamping on lazily: the first socket that asks for it schedules a
    deferred work item, and until that has run a datagram is stamped when it is *read* (on a busy
    machine, for tens of ms). A socket of this helper keeps stamping on for the block (closing the
    last such socket switches it off again, as lazily), after a probe datagram has come back stamped
    with its arrival."""
    import socket

    from lapwrench.drivers import arrival

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(("127.0.0.1", 0))
        tx.connect(rx.getsockname())
        assert arrival.enable(rx)
        deadline = time.monotonic() + timeout
        while True:
            tx.send(b"probe")
            time.sleep(0.02)
            _, stamp = arrival.recv_stamped(rx, 64)
            if stamp is not None and time.time() - stamp >= 0.015:
                break
            if time.monotonic() > deadline:
                pytest.fail(f"the kernel did not stamp datagrams on arrival within {timeout} s")
        yield
    finally:
        rx.close()
        tx.close()
