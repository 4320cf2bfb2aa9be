"""The gains of the simulated arm's internal joint position servo (a Franka-like joint impedance)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lapwrench.robot.description import ARM_SPECS


@dataclass(frozen=True)
class JointServoGains:
    """Joint stiffness (N m/rad) and damping (N m s/rad) of the internal joint position servo, one
    value per joint (a robot's defaults: :meth:`for_robot`, from its spec).
    """

    stiffness: tuple[float, ...]
    damping: tuple[float, ...]

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            v = np.asarray(getattr(self, name), float)
            if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"gains.{name} must be positive finite numbers, one per joint, "
                                 f"got {getattr(self, name)!r}")
        if len(self.stiffness) != len(self.damping):
            raise ValueError(f"gains.stiffness and gains.damping differ in length ({len(self.stiffness)} vs "
                             f"{len(self.damping)})")

    @classmethod
    def for_robot(cls, kind: str) -> JointServoGains:
        """The servo gains of robot ``kind``'s spec (:data:`~lapwrench.robot.description.ARM_SPECS`)."""
        spec = ARM_SPECS[kind]
        return cls(spec.servo_stiffness, spec.servo_damping)
