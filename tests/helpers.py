"""Helpers shared by the tests."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pytest

from lapwrench.robot.model import RobotModel

if TYPE_CHECKING:
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
