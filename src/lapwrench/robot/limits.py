"""Franka joint limits (position, velocity, acceleration, jerk, torque, torque rate).

Velocity/acceleration/jerk/torque values are the ones libfranka enforces on real hardware
(Franka datasheets; table in DEVELOPERS.md). Position limits come from the robot description.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from lapwrench.robot.description import build_urdf
from lapwrench.spatial import Vec

_TABLE: dict[str, dict[str, list[float]]] = {
    "panda": {
        "velocity": [2.175] * 4 + [2.61] * 3,
        "acceleration": [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0],
        "jerk": [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0],
        "torque": [87.0] * 4 + [12.0] * 3,
        "torque_rate": [1000.0] * 7,
    },
    "fr3": {
        "velocity": [2.62] * 4 + [5.26, 4.18, 5.26],
        "acceleration": [10.0] * 7,
        "jerk": [5000.0] * 7,
        "torque": [87.0] * 4 + [12.0] * 3,
        "torque_rate": [1000.0] * 7,
    },
}


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits of one robot model (arrays of the arm's joint count)."""

    position_lower: Vec
    position_upper: Vec
    velocity: Vec
    acceleration: Vec
    jerk: Vec
    torque: Vec
    torque_rate: Vec

    def scaled(self, fraction: float) -> JointLimits:
        """Velocity, acceleration and jerk limits scaled by ``fraction`` (a safety margin)."""
        return JointLimits(
            self.position_lower,
            self.position_upper,
            self.velocity * fraction,
            self.acceleration * fraction,
            self.jerk * fraction,
            self.torque,
            self.torque_rate,
        )


def franka_limits(kind: str, model: pin.Model | None = None) -> JointLimits:
    """The Franka limits of ``kind`` ('panda' or 'fr3'); position limits from ``model`` (by default the
    Pinocchio model of the arm's description, as :class:`~lapwrench.robot.model.RobotModel` builds it)."""
    if kind not in _TABLE:
        raise ValueError(f"no limit table for robot {kind!r}; choose one of {sorted(_TABLE)}")
    t = {k: np.array(v, dtype=float) for k, v in _TABLE[kind].items()}
    if model is None:
        model = pin.buildModelFromXML(build_urdf(kind))  # type: ignore[arg-type]
    return JointLimits(
        np.array(model.lowerPositionLimit, dtype=float),
        np.array(model.upperPositionLimit, dtype=float),
        t["velocity"],
        t["acceleration"],
        t["jerk"],
        t["torque"],
        t["torque_rate"],
    )


def joint_torque_limits(kind: str) -> Vec:
    """The joint torque limits (N m) of ``kind``, one per joint (the simulator's servo clip)."""
    if kind not in _TABLE:
        raise ValueError(f"no limit table for robot {kind!r}; choose one of {sorted(_TABLE)}")
    return np.array(_TABLE[kind]["torque"], dtype=float)


def limit_usage(q_ref: np.ndarray, dt: float, limits: JointLimits, q_start: Vec | None = None) -> dict[str, float]:
    """Largest fraction of each limit used by a reference sequence (T x joints), as libfranka sees it.

    Velocity, acceleration and jerk are the backward differences of the commanded positions,
    starting from rest at ``q_start`` (default: the first reference). A value <= 1 means inside.
    """
    q = np.asarray(q_ref, dtype=float)
    start = q[:1] if q_start is None else np.asarray(q_start, dtype=float)[None]
    q = np.vstack([start, start, start, q])
    v = np.diff(q, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    j = np.diff(a, axis=0) / dt
    below = np.max((limits.position_lower - q) / np.maximum(limits.position_upper - limits.position_lower, 1e-9))
    above = np.max((q - limits.position_upper) / np.maximum(limits.position_upper - limits.position_lower, 1e-9))
    return {
        "position_excess": float(max(below, above, 0.0)),
        "velocity": float(np.max(np.abs(v) / limits.velocity)),
        "acceleration": float(np.max(np.abs(a) / limits.acceleration)),
        "jerk": float(np.max(np.abs(j) / limits.jerk)),
    }
