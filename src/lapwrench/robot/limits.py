"""Joint limits of an arm (position, velocity, acceleration, jerk, torque, torque rate).

Velocity/acceleration/jerk/torque/torque-rate values are the arm's spec's tables
(:mod:`lapwrench.robot.arms`, each with its published source: for the Franka arms, the limits
libfranka enforces). Position limits come from the robot description.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import build_urdf
from lapwrench.spatial import Vec


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


def arm_limits(kind: str, model: pin.Model | None = None) -> JointLimits:
    """The limits of arm ``kind`` (its spec's tables); position limits from ``model`` (by default the
    Pinocchio model of the arm's description, as :class:`~lapwrench.robot.model.RobotModel` builds it).
    ``ValueError`` for an arm that is not registered."""
    t = arm_spec(kind).limits
    if model is None:
        model = pin.buildModelFromXML(build_urdf(kind))
    return JointLimits(
        np.array(model.lowerPositionLimit, dtype=float),
        np.array(model.upperPositionLimit, dtype=float),
        np.array(t.velocity, dtype=float),
        np.array(t.acceleration, dtype=float),
        np.array(t.jerk, dtype=float),
        np.array(t.torque, dtype=float),
        np.array(t.torque_rate, dtype=float),
    )


franka_limits = arm_limits
"""The former name of :func:`arm_limits` (from when only the Franka arms shipped)."""


def joint_torque_limits(kind: str) -> Vec:
    """The joint torque limits (N m) of ``kind``, one per joint (the simulator's servo clip)."""
    return np.array(arm_spec(kind).limits.torque, dtype=float)


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
