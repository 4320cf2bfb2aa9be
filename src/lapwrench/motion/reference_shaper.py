"""Shapes joint position references so they never break the Franka limits.

libfranka differentiates the commanded positions: v = Δq/dt, a = Δv/dt, j = Δa/dt. Each tick the
shaper takes the desired next velocity and clamps, per joint, the acceleration to the interval
allowed by

1. the jerk limit around the previous acceleration,
2. the acceleration limit,
3. the velocity limit, keeping room to ramp the acceleration back to zero at the jerk limit,
4. the position limits: the velocity toward a limit must let the joint stop before it with a
   braking deceleration (half the acceleration limit, leaving room for the jerk ramp),

with precedence jerk > acceleration > velocity/position when the bands do not intersect (the
position margin absorbs the rare overshoot). Limits are the robot's
scaled by ``limit_fraction``; positions keep ``position_margin`` clear of the hard limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lapwrench.robot.limits import JointLimits
from lapwrench.spatial import Vec


@dataclass
class ReferenceState:
    q: Vec
    dq: Vec
    ddq: Vec


class ReferenceShaper:
    def __init__(self, limits: JointLimits, dt: float, limit_fraction: float, position_margin: float) -> None:
        self.lim = limits.scaled(limit_fraction)
        self.dt = dt
        self.q_lo = limits.position_lower + position_margin
        self.q_hi = limits.position_upper - position_margin
        self.two_a_brake = self.lim.acceleration  # braking at half the acceleration limit
        self.jerk_step = self.lim.jerk * dt
        self.two_over_jerk = 2.0 / self.lim.jerk
        self.clamped_ticks = 0

    def _velocity_bounds(self, q: Vec) -> tuple[Vec, Vec]:
        """Velocity band at q: the velocity limit, and the speed from which braking at a_brake stops
        the joint at its position margin, v² = 2 a_brake (room to the limit)."""
        v_hi = np.minimum(self.lim.velocity, np.sqrt(self.two_a_brake * np.maximum(self.q_hi - q, 0.0)))
        v_lo = -np.minimum(self.lim.velocity, np.sqrt(self.two_a_brake * np.maximum(q - self.q_lo, 0.0)))
        return v_lo, v_hi

    def _reachable_acceleration(self, headroom: Vec) -> Vec:
        """Largest a with v + a dt + a²/(2 j) <= v + headroom: the velocity still fits after a
        jerk-limited ramp of the acceleration back to zero. Negative headroom brakes at once."""
        dt, j = self.dt, self.lim.jerk
        a = j * (np.sqrt(dt * dt + self.two_over_jerk * np.maximum(headroom, 0.0)) - dt)
        return np.where(headroom >= 0.0, a, headroom / dt)

    def step(self, state: ReferenceState, dq_desired: Vec) -> ReferenceState:
        """The next reference (q⁺, q̇⁺, q̈⁺) closest to ``dq_desired`` that respects every limit."""
        dt = self.dt
        a_des = (dq_desired - state.dq) / dt
        if not np.isfinite(a_des).all():
            a_des = -state.dq / dt  # never propagate a NaN: brake instead
        v_lo, v_hi = self._velocity_bounds(state.q + state.dq * dt)
        a_max = self.lim.acceleration
        a_lo = np.minimum(np.maximum(-self._reachable_acceleration(state.dq - v_lo), -a_max), a_max)
        a_hi = np.minimum(np.maximum(self._reachable_acceleration(v_hi - state.dq), -a_max), a_max)
        j_lo = state.ddq - self.jerk_step
        j_hi = state.ddq + self.jerk_step
        a_lo = np.minimum(np.maximum(a_lo, j_lo), j_hi)
        a_hi = np.maximum(np.minimum(np.maximum(a_hi, j_lo), j_hi), a_lo)
        a = np.minimum(np.maximum(a_des, a_lo), a_hi)
        if (a != a_des).any():
            self.clamped_ticks += 1
        dq = state.dq + a * dt
        return ReferenceState(state.q + dq * dt, dq, a)
