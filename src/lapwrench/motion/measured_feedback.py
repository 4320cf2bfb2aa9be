"""Feedback of the measured pose into the RCM task and the depth walls.

The controller integrates its virtual model into references; the robot follows them through its
joint servo, which gives way under load. A 30 N push on the handle of a Franka at its default joint
impedance moves the flange about 5 mm off the reference (measured in the MuJoCo world), and with it
the shaft in the incision. The reference then keeps the RCM while the real scope does not.

This filter measures what the robot adds: the RCM error and the tip depth at the *measured* joints
minus the same quantities at the reference, low-passed with ``FEEDBACK_TIME`` and capped. The RCM
task acts on e_R + offset (eq 14 with the offset added), so the reference leans against the
deflection until the measured error is gone; the envelope's depth walls use depth + offset, so the
real scope, not the reference, stops at the wall.
"""

from __future__ import annotations

import math

import numpy as np

from lapwrench.rcm.geometry import insertion_depth, rcm_error
from lapwrench.robot.model import Kinematics, RobotModel
from lapwrench.spatial import Vec

FEEDBACK_TIME = 0.01  # s, time constant of the low-pass on the measured-minus-reference offsets


class MeasuredFeedback:
    """Low-passed (measured - reference) RCM error (m, 3-vector) and tip depth (m), capped at ``cap``."""

    def __init__(self, model: RobotModel, length: float, dt: float, cap: float) -> None:
        self.model = model
        self.length = length
        self.gain = dt / max(FEEDBACK_TIME, dt)
        self.cap = cap
        self.e_offset = np.zeros(3)
        self.depth_offset = 0.0

    def reset(self) -> None:
        self.e_offset = np.zeros(3)
        self.depth_offset = 0.0

    def update(self, q_measured: Vec | None, kin: Kinematics, p_R: Vec, e_R: Vec) -> None:
        """One filter step; ``None`` (no valid measurement) lets the offsets decay to zero."""
        if q_measured is None:
            e_target, d_target = np.zeros(3), 0.0
        else:
            axis = self.model.scope_axis_at(q_measured)
            e_target = rcm_error(axis, p_R) - e_R  # type: ignore[arg-type]
            d_target = insertion_depth(axis, p_R, self.length) - insertion_depth(kin, p_R, self.length)  # type: ignore[arg-type]
            if not (np.isfinite(e_target).all() and math.isfinite(d_target)):
                e_target, d_target = np.zeros(3), 0.0
        self.e_offset = self.e_offset + self.gain * (e_target - self.e_offset)
        n = math.sqrt(float(self.e_offset @ self.e_offset))
        if n > self.cap:
            self.e_offset *= self.cap / n
        d = self.depth_offset + self.gain * (d_target - self.depth_offset)
        self.depth_offset = min(self.cap, max(-self.cap, d))
