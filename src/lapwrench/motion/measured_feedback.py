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

from lapwrench.jit import kernel_inlined
from lapwrench.rcm.geometry import insertion_depth, rcm_error
from lapwrench.robot.model import Kinematics, RobotModel, ScopeAxis
from lapwrench.spatial import Mat, Vec, all_finite, inner

FEEDBACK_TIME = 0.01  # s, time constant of the low-pass on the measured-minus-reference offsets
NO_AXIS = ScopeAxis(np.zeros(3), np.array([0.0, 0.0, 1.0]), np.diag([1.0, 1.0, 0.0]))  # "no measurement"
# The same as a placement of {E} (rotation column-major, as Pinocchio's; origin), whose axis is NO_AXIS.
NO_PLACEMENT = (np.asfortranarray(np.eye(3)), np.zeros(3))


@kernel_inlined
def feedback_step(
    offsets: Vec, measured: ScopeAxis, has_measured: bool, kin: Kinematics | ScopeAxis, p_R: Vec, e_R: Vec,
    length: float, gain: float, cap: float,
) -> None:
    """One low-pass step of ``offsets`` = [e_offset (3); depth_offset] in place (module docstring).

    ``measured`` is the scope axis at the measured joints; without one (``has_measured`` False) or
    with a non-finite one the targets are zero and the offsets decay.
    """
    e_target = np.zeros(3)
    d_target = 0.0
    if has_measured:
        e_t = rcm_error(measured, p_R)
        for i in range(3):
            e_t[i] -= e_R[i]
        d_t = insertion_depth(measured, p_R, length) - insertion_depth(kin, p_R, length)
        if all_finite(e_t) and math.isfinite(d_t):
            e_target, d_target = e_t, d_t
    e = offsets[:3]  # stepped in place
    for i in range(3):
        e[i] = offsets[i] + gain * (e_target[i] - offsets[i])
    n = math.sqrt(inner(e, e))
    if n > cap:
        for i in range(3):
            e[i] = e[i] * (cap / n)
    d = offsets[3] + gain * (d_target - offsets[3])
    offsets[3] = min(cap, max(-cap, d))


class MeasuredFeedback:
    """Low-passed (measured - reference) RCM error (m, 3-vector) and tip depth (m), capped at ``cap``."""

    def __init__(self, model: RobotModel, length: float, dt: float, cap: float) -> None:
        self.model = model
        self.length = length
        self.gain = dt / max(FEEDBACK_TIME, dt)
        self.cap = cap
        self.offsets = np.zeros(4)

    @property
    def e_offset(self) -> Vec:
        return self.offsets[:3]

    @property
    def depth_offset(self) -> float:
        return float(self.offsets[3])

    def reset(self) -> None:
        self.offsets[:] = 0.0

    def measured_axis(self, q_measured: Vec | None) -> tuple[ScopeAxis, bool]:
        """The scope axis at the measured joints (Pinocchio), or a placeholder and False when there is none.
        The axis is the model's own arrays (:meth:`RobotModel.scope_axis_into`): valid until its next call."""
        if q_measured is None:
            return NO_AXIS, False
        return self.model.scope_axis_into(q_measured), True

    def measured_placement(self, q_measured: Vec | None) -> tuple[Mat, Vec, bool]:
        """{E}'s rotation and origin at the measured joints (Pinocchio, :meth:`RobotModel.placement_E_into`),
        or :data:`NO_PLACEMENT` and False when there is none: what the compiled tick takes the measured
        scope axis from. Valid until the model's next call."""
        if q_measured is None:
            return NO_PLACEMENT[0], NO_PLACEMENT[1], False
        R, p = self.model.placement_E_into(q_measured)
        return R, p, True

    def update(self, q_measured: Vec | None, kin: Kinematics, p_R: Vec, e_R: Vec) -> None:
        """One filter step; ``None`` (no valid measurement) lets the offsets decay to zero."""
        axis, has = self.measured_axis(q_measured)
        feedback_step(self.offsets, axis, has, kin, p_R, e_R, self.length, self.gain, self.cap)
