"""Joint-limit intervals for the next reference, so it never breaks the Franka limits.

libfranka differentiates the commanded positions: v = Δq/dt, a = Δv/dt, j = Δa/dt. Each tick the
shaper gives, per joint, the interval of accelerations allowed by

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
        self._toward = np.array([[1.0], [-1.0]])  # +dq eats the lower room, -dq the upper one
        self.clamped_ticks = 0

    def _braking_speeds(self, q: Vec) -> Vec:
        """Largest speeds (2 x n: toward the lower, toward the upper limit) at q: the velocity limit,
        and the speed from which braking at a_brake stops the joint at its margin, v² = 2 a_brake room."""
        room = np.maximum(np.stack((q - self.q_lo, self.q_hi - q)), 0.0)
        return np.minimum(self.lim.velocity, np.sqrt(self.two_a_brake * room))

    def _reachable_acceleration(self, headroom: Vec) -> Vec:
        """Largest a with v + a dt + a²/(2 j) <= v + headroom: the velocity still fits after a
        jerk-limited ramp of the acceleration back to zero. Negative headroom brakes at once."""
        dt, j = self.dt, self.lim.jerk
        a = j * (np.sqrt(dt * dt + self.two_over_jerk * np.maximum(headroom, 0.0)) - dt)
        return np.where(headroom >= 0.0, a, headroom / dt)

    def acceleration_bounds(self, state: ReferenceState) -> tuple[Vec, Vec]:
        """Per-joint interval [a_lo, a_hi] of next accelerations that respects every joint limit.

        Precedence jerk > acceleration > velocity/position when the bands do not intersect, so the
        interval is never empty. The saturation step (:mod:`lapwrench.motion.saturation`) chooses an
        acceleration inside it that keeps the RCM task.
        """
        # rows: [lower bound, upper bound] of the acceleration
        headroom = self._braking_speeds(state.q + state.dq * self.dt) + self._toward * state.dq
        bounds = self._toward * -self._reachable_acceleration(headroom)
        a_max = self.lim.acceleration
        bounds = np.minimum(np.maximum(bounds, -a_max), a_max)
        bounds = np.minimum(np.maximum(bounds, state.ddq - self.jerk_step), state.ddq + self.jerk_step)
        return bounds[0], np.maximum(bounds[1], bounds[0])

    def advance(self, state: ReferenceState, a: Vec, bounds: tuple[Vec, Vec] | None = None) -> ReferenceState:
        """The next reference with acceleration ``a``, clipped into ``bounds`` (default: computed).

        The clip is the last guard of the robot's limits; :attr:`clamped_ticks` counts the ticks where
        it changed ``a`` by more than round-off (never, when the saturation step found a solution).
        """
        a_lo, a_hi = self.acceleration_bounds(state) if bounds is None else bounds
        if not np.isfinite(a).all():
            a = -state.dq / self.dt  # never propagate a NaN: brake instead
        a_clip = np.minimum(np.maximum(a, a_lo), a_hi)
        if np.max(np.abs(a_clip - a)) > 1e-9 * (1.0 + np.max(np.abs(a))):
            self.clamped_ticks += 1
        dq = state.dq + a_clip * self.dt
        return ReferenceState(state.q + dq * self.dt, dq, a_clip)

    def step(self, state: ReferenceState, dq_desired: Vec) -> ReferenceState:
        """The next reference (q⁺, q̇⁺, q̈⁺) closest to ``dq_desired`` with each joint clamped on its own.

        Per-joint clamping does not keep a task; the controller uses :meth:`acceleration_bounds`
        with the saturation step instead. This stays for tests and for motions without a task.
        """
        return self.advance(state, (dq_desired - state.dq) / self.dt)
