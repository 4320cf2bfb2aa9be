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

from typing import NamedTuple

import numpy as np

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.robot.limits import JointLimits
from lapwrench.spatial import Vec, all_finite


class ReferenceState(NamedTuple):
    """The joint reference (q, q̇, q̈) of one tick (a named tuple: the controller builds one every millisecond)."""

    q: Vec
    dq: Vec
    ddq: Vec


@kernel
def braking_speeds(q: float, q_lo: float, q_hi: float, v_max: float, two_a_brake: float) -> tuple[float, float]:
    """Largest speeds of one joint at q toward its lower and toward its upper limit: the velocity limit,
    and the speed from which braking at a_brake stops the joint at its margin, v² = 2 a_brake room."""
    down = np.minimum(v_max, np.sqrt(two_a_brake * np.maximum(q - q_lo, 0.0)))
    up = np.minimum(v_max, np.sqrt(two_a_brake * np.maximum(q_hi - q, 0.0)))
    return down, up


@kernel
def reachable_acceleration(headroom: float, j_max: float, dt: float) -> float:
    """Largest a of one joint with v + a dt + a²/(2 j) <= v + headroom: the velocity still fits after a
    jerk-limited ramp of the acceleration back to zero. Negative headroom brakes at once."""
    if headroom >= 0.0:
        return j_max * (np.sqrt(dt * dt + 2.0 / j_max * headroom) - dt)
    return headroom / dt


@kernel_inlined
def acceleration_bounds(
    q: Vec, dq: Vec, ddq: Vec, q_lo: Vec, q_hi: Vec, v_max: Vec, a_max: Vec, j_max: Vec, dt: float
) -> tuple[Vec, Vec]:
    """Per-joint interval [a_lo, a_hi] of next accelerations that respects every joint limit.

    Precedence jerk > acceleration > velocity/position when the bands do not intersect, so the
    interval is never empty. The saturation step (:mod:`lapwrench.motion.saturation`) chooses an
    acceleration inside it that keeps the RCM task.
    """
    n = q.shape[0]
    bounds = np.empty((2, n))  # rows a_lo, a_hi: one allocation
    a_lo, a_hi = bounds[0], bounds[1]
    for i in range(n):  # joint by joint: scalars, no temporary arrays
        down, up = braking_speeds(q[i] + dq[i] * dt, q_lo[i], q_hi[i], v_max[i], a_max[i])  # braking at half a_max
        lo = -reachable_acceleration(down + dq[i], j_max[i], dt)
        hi = reachable_acceleration(up - dq[i], j_max[i], dt)
        jerk_step = j_max[i] * dt
        a = a_max[i]
        lo = np.minimum(np.maximum(np.minimum(np.maximum(lo, -a), a), ddq[i] - jerk_step), ddq[i] + jerk_step)
        hi = np.minimum(np.maximum(np.minimum(np.maximum(hi, -a), a), ddq[i] - jerk_step), ddq[i] + jerk_step)
        a_lo[i], a_hi[i] = lo, np.maximum(hi, lo)
    return a_lo, a_hi


@kernel_inlined
def advance_reference(
    q: Vec, dq: Vec, a: Vec, a_lo: Vec, a_hi: Vec, dt: float
) -> tuple[Vec, Vec, Vec, bool]:
    """The next reference (q⁺, q̇⁺, q̈⁺) with acceleration ``a`` clipped into [a_lo, a_hi], and whether
    the clip changed ``a`` by more than round-off. A non-finite ``a`` brakes instead."""
    if not all_finite(a):
        a = -dq / dt  # never propagate a NaN: brake instead
    n = q.shape[0]
    rows = np.empty((3, n))  # q⁺, q̇⁺, the clipped acceleration: one allocation
    q_next, dq_next, a_clip = rows[0], rows[1], rows[2]
    change, size = 0.0, 0.0  # max |a_clip - a|, max |a|
    for i in range(n):
        a_clip[i] = np.minimum(np.maximum(a[i], a_lo[i]), a_hi[i])
        change = max(change, abs(a_clip[i] - a[i]))
        size = max(size, abs(a[i]))
        dq_next[i] = dq[i] + a_clip[i] * dt
        q_next[i] = q[i] + dq_next[i] * dt
    clamped = change > 1e-9 * (1.0 + size)
    return q_next, dq_next, a_clip, clamped


class ReferenceShaper:
    def __init__(self, limits: JointLimits, dt: float, limit_fraction: float, position_margin: float) -> None:
        self.lim = limits.scaled(limit_fraction)
        self.dt = dt
        self.q_lo = limits.position_lower + position_margin
        self.q_hi = limits.position_upper - position_margin
        self.clamped_ticks = 0

    def acceleration_bounds(self, state: ReferenceState) -> tuple[Vec, Vec]:
        """Per-joint interval [a_lo, a_hi] of next accelerations (:func:`acceleration_bounds`)."""
        lim = self.lim
        return acceleration_bounds(
            state.q, state.dq, state.ddq, self.q_lo, self.q_hi, lim.velocity, lim.acceleration, lim.jerk, self.dt
        )

    def advance(self, state: ReferenceState, a: Vec, bounds: tuple[Vec, Vec] | None = None) -> ReferenceState:
        """The next reference with acceleration ``a``, clipped into ``bounds`` (default: computed).

        The clip is the last guard of the robot's limits; :attr:`clamped_ticks` counts the ticks where
        it changed ``a`` by more than round-off (never, when the saturation step found a solution).
        """
        a_lo, a_hi = self.acceleration_bounds(state) if bounds is None else bounds
        q, dq, ddq, clamped = advance_reference(state.q, state.dq, np.asarray(a, dtype=float), a_lo, a_hi, self.dt)
        self.clamped_ticks += bool(clamped)
        return ReferenceState(q, dq, ddq)

    def step(self, state: ReferenceState, dq_desired: Vec) -> ReferenceState:
        """The next reference (q⁺, q̇⁺, q̈⁺) closest to ``dq_desired`` with each joint clamped on its own.

        Per-joint clamping does not keep a task; the controller uses :meth:`acceleration_bounds`
        with the saturation step instead. This stays for tests and for motions without a task.
        """
        return self.advance(state, (dq_desired - state.dq) / self.dt)
