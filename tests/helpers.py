"""Helpers shared by the tests."""

from __future__ import annotations

import numpy as np

from lapwrench.robot.model import RobotModel


def random_configuration(model: RobotModel, rng: np.random.Generator) -> np.ndarray:
    lo, hi = model.limits.position_lower, model.limits.position_upper
    return lo + (hi - lo) * (0.1 + 0.8 * rng.random(7))
