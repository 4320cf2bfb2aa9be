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
from lapwrench.robot.model import Kinematics
from lapwrench.spatial import Mat, Vec

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


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def insertion_rate_weights(d: tuple[float, float, float], r: tuple[float, float, float]) -> list[float]:
    """Weights w of the twist [ω; v] of {E} with depth rate = wᵀ [ω; v] (so the row is wᵀ J_E):

        d/dt [L - d_zᵀ (p_R - p_E)] = d_zᵀ v_E - (d_z × r)ᵀ ω_E,   r = p_R - p_E.

    (The motion of the adaptive point p_R is left out: it is slow and not the arm's doing.)
    """
    k = _cross(d, r)
    return [-k[0], -k[1], -k[2], d[0], d[1], d[2]]


def roll_angle(R_E: Mat, R_E0: Mat) -> float:
    """Rotation (rad) of {E} about its shaft axis since ``R_E0`` (the twist of a swing-twist split).

    The start frame's x axis is carried by the shortest rotation taking the start axis d_0 to the
    current d_z; the roll is the angle from that axis to the current x axis, about d_z.
    """
    (x0, _, d0), (x, _, d) = (tuple(c) for c in R_E0.T.tolist()), (tuple(c) for c in R_E.T.tolist())
    k = _cross(d0, d)
    kx0 = _cross(k, x0)
    kkx0 = _cross(k, kx0)
    c = 1.0 + _dot(d0, d)
    x0s = (x0[0] + kx0[0] + kkx0[0] / c, x0[1] + kx0[1] + kkx0[1] / c, x0[2] + kx0[2] + kkx0[2] / c)
    return math.atan2(_dot(_cross(x0s, x), d), _dot(x0s, x))


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
        """The envelope's rows at this tick, on the *twist* acceleration of {E} (map them to the joints
        with :meth:`LimitRows.through` ``(kin.J_E)``). ``a_d`` (the desired acceleration) orients the
        pivot rows when the scope is at rest; ``depth_offset`` (m) is what the measured pose adds."""
        cfg, dt = self.cfg, self.dt
        if not cfg.enabled or self.R_E0 is None:
            return None
        d = tuple(kin.d_z.tolist())
        r = tuple((p_R - kin.p_E).tolist())
        twist_v = kin.J_E @ kin.dq
        twist = twist_v.tolist()
        # pivot: |ω⊥| bounded along its current direction u1 and across it (u2), so the polygon
        # re-aligned every tick keeps the norm at the limit; from rest, along the desired motion
        w = (twist[0], twist[1], twist[2])
        if _perp_norm2(w, d) < 1e-12:
            w = tuple((kin.J_E[:3] @ (kin.dq + dt * a_d)).tolist())
        wd = _dot(w, d)
        u = (w[0] - wd * d[0], w[1] - wd * d[1], w[2] - wd * d[2])
        n = math.sqrt(_dot(u, u))
        u1 = (u[0] / n, u[1] / n, u[2] / n) if n > 1e-9 else tuple(kin.R_E[:, 0].tolist())
        u2 = _cross(d, u1)
        W = np.array(
            (insertion_rate_weights(d, r), (*u1, 0.0, 0.0, 0.0), (*u2, 0.0, 0.0, 0.0), (*d, 0.0, 0.0, 0.0))
        )
        y = (W @ twist_v).tolist()
        # position walls: the room left once the rate has followed its bound (it lags by T)
        T = max(APPROACH_TIME, dt)
        depth = self.length - _dot(d, r) + depth_offset
        v_max, a_in = cfg.insertion_speed_max, cfg.insertion_deceleration
        v_in = wall_speed(cfg.depth_max - DEPTH_WALL_MARGIN - depth - max(y[0], 0.0) * T, a_in, v_max)
        v_out = wall_speed(depth - cfg.depth_min - DEPTH_WALL_MARGIN + min(y[0], 0.0) * T, a_in, v_max)
        roll = roll_angle(kin.R_E, self.R_E0)
        r_max, a_w = cfg.roll_speed_max, cfg.pivot_deceleration
        w_pos = wall_speed(cfg.roll_range - roll - max(y[3], 0.0) * T, a_w, r_max)
        w_neg = wall_speed(roll + cfg.roll_range + min(y[3], 0.0) * T, a_w, r_max)
        p_max = cfg.pivot_speed_max
        limits = ((-v_out, v_in, a_in), (-p_max, p_max, a_w), (-p_max, p_max, a_w), (-w_neg, w_pos, a_w))
        bounds = [rate_row_bounds(y_k, *lim, dt) for y_k, lim in zip(y, limits, strict=True)]
        names = (
            _wall_name(v_out, v_in, v_max, "depth_min", "depth_max", "insertion_speed"),
            "pivot_speed",
            "pivot_speed",
            _wall_name(w_neg, w_pos, r_max, "roll_range", "roll_range", "roll_speed"),
        )
        lo, hi = np.array(bounds).T
        return LimitRows(W, lo, hi, np.array((a_in, a_w, a_w, a_w)), names, _SOFT)


def _perp_norm2(w: tuple[float, float, float], d: tuple[float, float, float]) -> float:
    """|P w|² for the projector P orthogonal to d."""
    wd = _dot(w, d)
    return _dot(w, w) - wd * wd


_SOFT = np.zeros(4, dtype=bool)
_SOFT.flags.writeable = False
