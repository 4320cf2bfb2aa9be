"""The gains of the simulated arm's internal joint position servo (a Franka-like joint impedance)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class JointServoGains:
    """Joint stiffness (N m/rad) and damping (N m s/rad) of the internal joint position servo.

    Stiffness: libfranka's default joint impedance. Damping: about critical with the arm's inertia
    plus armature near the default configuration.
    """

    stiffness: tuple[float, ...] = (3000.0, 3000.0, 3000.0, 2500.0, 2500.0, 2000.0, 2000.0)
    damping: tuple[float, ...] = (150.0, 150.0, 110.0, 100.0, 40.0, 40.0, 30.0)

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (7,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"gains.{name} must be 7 positive finite numbers, got {getattr(self, name)!r}")
