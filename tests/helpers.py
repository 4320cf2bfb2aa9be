"""Helpers shared by the tests."""

from __future__ import annotations

import os
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
