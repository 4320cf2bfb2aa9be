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

import numpy as np

from lapwrench.config import EnvelopeConfig
from lapwrench.motion.saturation import LimitRows
from lapwrench.rcm.geometry import insertion_depth
from lapwrench.robot.model import Kinematics
from lapwrench.spatial import Mat, Vec, cross

# Time constant (s) with which a rate approaches its envelope limit.
APPROACH_TIME = 0.01
# The depth walls stand this far (m) inside the configured range: the robot's joint servo carries
# the scope past a reference that brakes at the wall (0.32 mm measured in the MuJoCo world with the
# Franka's joint impedance at 10 and 30 N axial pushes, whatever the measured-feedback time).
DEPTH_WALL_MARGIN = 0.0005


def wall_speed(room: float, deceleration: float, speed_max: float) -> float:
    """Largest speed toward a wall ``room`` away: sqrt(2 a room), from which ``deceleration`` stops
    at the wall, and at most ``speed_max``.

    Beyond the wall (room < 0) the result is negative: the scope is led back at the same law.
    """
    v = math.copysign(math.sqrt(2.0 * deceleration * abs(room)), room)
    return min(speed_max, max(-speed_max, v))


def _wall_name(v_lo: float, v_hi: float, speed_max: float, lo_name: str, hi_name: str, speed_name: str) -> str:
    """Which wall a rate row stands for: a position wall when it is nearer than the speed limit."""
    if v_hi < speed_max:
        return hi_name
    if v_lo < speed_max:
        return lo_name
    return speed_name


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


def insertion_rate_row(kin: Kinematics, p_R: Vec) -> Vec:
    """Row c with depth rate = cᵀ θ̇: d/dt [L - d_zᵀ(p_R - p_E)] = d_zᵀ v_E - (d_z × r)ᵀ ω_E, r = p_R - p_E.

    (The motion of the adaptive point p_R is left out: it is slow and not the arm's doing.)
    """
    d = kin.d_z
    r = p_R - kin.p_E
    return d @ kin.J_E[3:] - cross(d, r) @ kin.J_E[:3]


def roll_angle(R_E: Mat, R_E0: Mat) -> float:
    """Rotation (rad) of {E} about its shaft axis since ``R_E0`` (the twist of a swing-twist split).

    The start frame's x axis is carried by the shortest rotation taking the start axis d_0 to the
    current d_z; the roll is the angle from that axis to the current x axis, about d_z.
    """
    d0, d = R_E0[:, 2], R_E[:, 2]
    x0, x = R_E0[:, 0], R_E[:, 0]
    k = cross(d0, d)
    x0s = x0 + cross(k, x0) + cross(k, cross(k, x0)) / (1.0 + float(d0 @ d))
    return math.atan2(float(cross(x0s, x) @ d), float(x0s @ x))


class Envelope:
    """Builds the envelope's limit rows each tick from the configuration (:class:`EnvelopeConfig`)."""

    def __init__(self, cfg: EnvelopeConfig, length: float, dt: float) -> None:
        self.cfg = cfg
        self.length = length
        self.dt = dt
        self.R_E0: Mat | None = None

    def reset(self, kin: Kinematics) -> None:
        """Take the roll reference (zero roll) at the start pose."""
        self.R_E0 = kin.R_E.copy()

    def rows(self, kin: Kinematics, p_R: Vec, a_d: Vec, depth_offset: float = 0.0) -> LimitRows | None:
        """The envelope's rows at this tick; ``a_d`` (the desired acceleration) orients the pivot row
        when the scope is at rest; ``depth_offset`` (m) is what the measured pose adds to the depth."""
        cfg, dt = self.cfg, self.dt
        if not cfg.enabled or self.R_E0 is None:
            return None
        dq, d = kin.dq, kin.d_z
        J_w = kin.J_E[:3]
        # pivot: |ω⊥| bounded along its current direction u1 and across it (u2), so the polygon
        # re-aligned every tick keeps the norm at the limit; from rest, along the desired motion
        w = kin.P @ (J_w @ dq)
        if w @ w < 1e-12:
            w = kin.P @ (J_w @ (dq + dt * a_d))
        w_norm = math.sqrt(float(w @ w))
        u1 = w / w_norm if w_norm > 1e-9 else kin.R_E[:, 0]
        C = np.empty((4, dq.shape[0]))
        C[0] = insertion_rate_row(kin, p_R)
        C[1:] = np.array((u1, cross(d, u1), d)) @ J_w
        y = C @ dq
        # position walls: the room left once the rate has followed its bound (it lags by T)
        T = max(APPROACH_TIME, dt)
        depth = insertion_depth(kin, p_R, self.length) + depth_offset
        v_max, a_in = cfg.insertion_speed_max, cfg.insertion_deceleration
        v_in = wall_speed(cfg.depth_max - DEPTH_WALL_MARGIN - depth - max(y[0], 0.0) * T, a_in, v_max)
        v_out = wall_speed(depth - cfg.depth_min - DEPTH_WALL_MARGIN + min(y[0], 0.0) * T, a_in, v_max)
        roll = roll_angle(kin.R_E, self.R_E0)
        r_max, a_w = cfg.roll_speed_max, cfg.pivot_deceleration
        w_pos = wall_speed(cfg.roll_range - roll - max(y[3], 0.0) * T, a_w, r_max)
        w_neg = wall_speed(roll + cfg.roll_range + min(y[3], 0.0) * T, a_w, r_max)
        p_max = cfg.pivot_speed_max
        limits = ((-v_out, v_in, a_in), (-p_max, p_max, a_w), (-p_max, p_max, a_w), (-w_neg, w_pos, a_w))
        bounds = [rate_row_bounds(float(y_k), *lim, dt) for y_k, lim in zip(y, limits, strict=True)]
        names = (
            _wall_name(v_out, v_in, v_max, "depth_min", "depth_max", "insertion_speed"),
            "pivot_speed",
            "pivot_speed",
            _wall_name(w_neg, w_pos, r_max, "roll_range", "roll_range", "roll_speed"),
        )
        lo, hi = np.array(bounds).T
        return LimitRows(C, lo, hi, np.array((a_in, a_w, a_w, a_w)), names, np.zeros(4, dtype=bool))
