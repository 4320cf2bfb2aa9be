"""The scope's task-space envelope as limit rows on the joint acceleration.

Each wall bounds one rate y = cᵀ θ̇ of the scope: the insertion speed (and through it the depth
range), the pivot angular speed, the roll speed (and through it the roll range). The next
reference's rate is y⁺ = cᵀ (θ̇ + a dt), so a bound y_lo <= y⁺ <= y_hi is the row

    (y_lo - y) / dt  <=  cᵀ a  <=  (y_hi - y) / dt.

A position wall (depth, roll) bounds the rate toward it by the speed from which the wall's
deceleration stops the scope at the wall, v = sqrt(2 a_wall room), so the hand meets a soft wall,
not a jerk. A rate already outside its bounds (after a config change, or pushed by the RCM task)
is brought back at no more than the wall's deceleration. The rows are lower priority than the
joint limits and go through :func:`lapwrench.motion.saturation.saturate_in_null_space`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lapwrench.config import EnvelopeConfig
from lapwrench.jit import kernel, kernel_inlined
from lapwrench.motion.saturation import LimitRows
from lapwrench.robot.model import Kinematics
from lapwrench.spatial import Mat, Vec, cross3, cross3_into, inner, matvec

# Time constant (s) with which a rate approaches its envelope limit.
APPROACH_TIME = 0.01
# The depth walls stand this far (m) inside the configured range: the robot's joint servo carries
# the scope past a reference that brakes at the wall (0.32 mm measured in the MuJoCo world with the
# Franka's joint impedance at 10 and 30 N axial pushes, whatever the measured-feedback time).
DEPTH_WALL_MARGIN = 0.0005
# Names of the walls a row can stand for (telemetry); :func:`envelope_rows` returns their indices.
WALL_NAMES = ("insertion_speed", "depth_min", "depth_max", "pivot_speed", "roll_range", "roll_speed")


class EnvelopeParams(NamedTuple):
    """The envelope configuration as one tuple of scalars for the compiled maths."""

    pivot_speed_max: float
    pivot_deceleration: float
    insertion_speed_max: float
    insertion_deceleration: float
    depth_min: float
    depth_max: float
    roll_range: float
    roll_speed_max: float

    @staticmethod
    def from_config(c: EnvelopeConfig) -> EnvelopeParams:
        return EnvelopeParams(
            float(c.pivot_speed_max), float(c.pivot_deceleration), float(c.insertion_speed_max),
            float(c.insertion_deceleration), float(c.depth_min), float(c.depth_max), float(c.roll_range),
            float(c.roll_speed_max),
        )


@kernel
def wall_speed(room: float, deceleration: float, speed_max: float) -> float:
    """Largest speed toward a wall ``room`` away: sqrt(2 a room), from which ``deceleration`` stops
    at the wall, and at most ``speed_max``.

    Beyond the wall (room < 0) the result is negative: the scope is led back at the same law.
    """
    v = math.copysign(math.sqrt(2.0 * deceleration * abs(room)), room)
    return min(speed_max, max(-speed_max, v))


@kernel
def _wall_code(v_lo: float, v_hi: float, speed_max: float, lo_code: int, hi_code: int, speed_code: int) -> int:
    """Which wall a rate row stands for: a position wall when it is nearer than the speed limit."""
    if v_hi < speed_max:
        return hi_code
    if v_lo < speed_max:
        return lo_code
    return speed_code


@kernel
def rate_row_bounds(y: float, y_lo: float, y_hi: float, deceleration: float, dt: float) -> tuple[float, float]:
    """Bounds on cᵀ a that bring the rate y toward [y_lo, y_hi] no faster than ``APPROACH_TIME``.

    (y_hi - y) / T bounds the acceleration, so it falls to zero smoothly as the rate reaches its
    limit (within the joints' jerk limits; a one-tick approach, T = dt, would ask for an arbitrary
    jerk and overshoot). A rate outside the interval is brought back at no more than ``deceleration``.
    """
    T = max(APPROACH_TIME, dt)
    lo = min((y_lo - y) / T, deceleration)
    hi = max((y_hi - y) / T, -deceleration)
    return lo, max(lo, hi)


@kernel
def insertion_rate_weights(d: Vec, r: Vec) -> Vec:
    """Weights w of the twist [ω; v] of {E} with depth rate = wᵀ [ω; v] (so the row is wᵀ J_E):

        d/dt [L - d_zᵀ (p_R - p_E)] = d_zᵀ v_E - (d_z × r)ᵀ ω_E,   r = p_R - p_E.

    (The motion of the adaptive point p_R is left out: it is slow and not the arm's doing.)
    """
    w = np.empty(6)
    cross3_into(d, r, w[:3])
    for i in range(3):
        w[i], w[i + 3] = -w[i], d[i]
    return w


ANTIPARALLEL = 1e-9  # 1 + d_0·d_z below which the shaft is taken as turned a half turn (roll_angle)


@kernel
def roll_angle(R_E: Mat, R_E0: Mat) -> float:
    """Rotation (rad) of {E} about its shaft axis since ``R_E0`` (the twist of a swing-twist split).

    The start frame's x axis is carried by the shortest rotation taking the start axis d_0 to the
    current d_z; the roll is the angle from that axis to the current x axis, about d_z. With d_z
    turned (within round-off) a half turn from d_0 no rotation is the shortest; the half turn about
    the start x axis is taken, which leaves that axis where it was.
    """
    x0, d0, x, d = R_E0[:, 0], R_E0[:, 2], R_E[:, 0], R_E[:, 2]  # columns as views
    c = 1.0 + inner(d0, d)
    if c < ANTIPARALLEL:
        return math.atan2(inner(cross3(x0, x), d), inner(x0, x))
    work = np.empty((5, 3))  # the vectors below as rows of one array: one allocation
    k, kx0, kkx0, x0s, x0s_x = work[0], work[1], work[2], work[3], work[4]
    cross3_into(d0, d, k)
    cross3_into(k, x0, kx0)
    cross3_into(k, kx0, kkx0)
    for i in range(3):
        x0s[i] = x0[i] + kx0[i] + kkx0[i] / c
    cross3_into(x0s, x, x0s_x)
    return math.atan2(inner(x0s_x, d), inner(x0s, x))


@kernel_inlined
def envelope_rows(
    kin: Kinematics, p_R: Vec, a_d: Vec, depth_offset: float, R_E0: Mat, p: EnvelopeParams, length: float, dt: float
) -> tuple[Mat, Vec, Vec, Vec, np.ndarray]:
    """The envelope's four rows lo <= W ẋ <= hi on the twist acceleration ẋ of {E} (module docstring).

    Rows: insertion (depth walls and speed), the pivot speed along and across the current pivot
    direction, the roll (range and speed). ``a_d`` (the desired joint acceleration) orients the
    pivot rows when the scope is at rest; ``depth_offset`` (m) is what the measured pose adds.
    Returns (W, lo, hi, scale, wall): ``wall`` indexes :data:`WALL_NAMES`.
    """
    d = kin.d_z
    r = p_R - kin.p_E
    twist = matvec(kin.J_E, kin.dq)
    # pivot: |ω⊥| bounded along its current direction u1 and across it (u2), so the polygon
    # re-aligned every tick keeps the norm at the limit; from rest, along the desired motion
    w = twist[:3]  # a view: read only
    wd = inner(w, d)
    if inner(w, w) - wd * wd < 1e-12:
        w = matvec(kin.J_E[:3], kin.dq + dt * a_d)
        wd = inner(w, d)
    W = np.zeros((4, 6))
    W[0] = insertion_rate_weights(d, r)
    u1, u2 = W[1, :3], W[2, :3]  # written in their rows
    for i in range(3):
        u1[i] = w[i] - wd * d[i]  # u = w - (w·d) d, then normalised in place
    n = math.sqrt(inner(u1, u1))
    for i in range(3):
        u1[i] = u1[i] / n if n > 1e-9 else kin.R_E[i, 0]
    cross3_into(d, u1, u2)
    W[3, :3] = d
    y = matvec(W, twist)
    # position walls: the room left once the rate has followed its bound (it lags by T)
    T = max(APPROACH_TIME, dt)
    depth = length - inner(d, r) + depth_offset
    v_max, a_in = p.insertion_speed_max, p.insertion_deceleration
    v_in = wall_speed(p.depth_max - DEPTH_WALL_MARGIN - depth - max(y[0], 0.0) * T, a_in, v_max)
    v_out = wall_speed(depth - p.depth_min - DEPTH_WALL_MARGIN + min(y[0], 0.0) * T, a_in, v_max)
    roll = roll_angle(kin.R_E, R_E0)
    r_max, a_w = p.roll_speed_max, p.pivot_deceleration
    w_pos = wall_speed(p.roll_range - roll - max(y[3], 0.0) * T, a_w, r_max)
    w_neg = wall_speed(roll + p.roll_range + min(y[3], 0.0) * T, a_w, r_max)
    p_max = p.pivot_speed_max
    bounds = np.empty((2, 4))  # rows lo, hi: one allocation
    lo, hi = bounds[0], bounds[1]
    lo[0], hi[0] = rate_row_bounds(y[0], -v_out, v_in, a_in, dt)
    lo[1], hi[1] = rate_row_bounds(y[1], -p_max, p_max, a_w, dt)
    lo[2], hi[2] = rate_row_bounds(y[2], -p_max, p_max, a_w, dt)
    lo[3], hi[3] = rate_row_bounds(y[3], -w_neg, w_pos, a_w, dt)
    scale = np.array((a_in, a_w, a_w, a_w))
    wall = np.array((_wall_code(v_out, v_in, v_max, 1, 2, 0), 3, 3, _wall_code(w_neg, w_pos, r_max, 4, 4, 5)))
    return W, lo, hi, scale, wall


class Envelope:
    """Builds the envelope's limit rows each tick from the configuration (:class:`EnvelopeConfig`)."""

    def __init__(self, cfg: EnvelopeConfig, length: float, dt: float) -> None:
        self.cfg = cfg
        self.params = EnvelopeParams.from_config(cfg)
        self.length = length
        self.dt = dt
        self.R_E0: Mat | None = None

    def reset(self, kin: Kinematics) -> None:
        """Take the roll reference (zero roll) at the start pose."""
        self.R_E0 = kin.R_E.copy()

    def rows(self, kin: Kinematics, p_R: Vec, a_d: Vec, depth_offset: float = 0.0) -> LimitRows | None:
        """The envelope's rows at this tick, on the *twist* acceleration of {E} (map them to the joints
        with :meth:`LimitRows.through` ``(kin.J_E)``); None when the envelope is off (see :func:`envelope_rows`)."""
        if not self.cfg.enabled or self.R_E0 is None:
            return None
        W, lo, hi, scale, wall = envelope_rows(
            kin, p_R, a_d, depth_offset, self.R_E0, self.params, self.length, self.dt
        )
        return LimitRows(W, lo, hi, scale, tuple(WALL_NAMES[i] for i in wall), _SOFT)


_SOFT = np.zeros(4, dtype=bool)
_SOFT.flags.writeable = False
