"""The simulated surgeon: a hand on the handle, instruments moving along task trajectories, and
the incision-housing disturbance.

The hand is a person steering the view: it pushes the handle sideways so the scope tip turns
toward a target axis while gripping with a chosen force, and lets go when the view is within
tolerance. Two styles:

- force-driven (``max_speed=None``): the push grows with the remaining angle and with how long the
  view has been lagging (proportional-integral, saturated) — the same effort whatever the grip, as
  in the paper's grip experiment (Fig. 4);
- speed-driven (``max_speed`` set): the hand adjusts its push so that the view turns at a
  comfortable rate, slowing down near the target, like a surgeon sweeping the view.

The F/T sensor measures whatever the hand applies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lapwrench.sim.world import SimWorld


def _norm(u: np.ndarray) -> float:
    """|u| as ``np.linalg.norm`` computes it for a vector (sqrt(u.dot(u))), bit for bit, without its overhead."""
    return math.sqrt(u.dot(u))


def _clip(x: float, lo: float, hi: float) -> float:
    """``np.clip`` of one number, bit for bit (NaN passes; at a tie ``x`` is kept, so -0.0 stays -0.0
    against a 0.0 bound, as numpy's does), without the cost of an array call: the hands call it every
    control period."""
    return min(max(x, lo), hi)


def across_shaft(v: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Unit vector of the part of ``v`` perpendicular to the shaft direction ``d``."""
    u = v - (v @ d) * d
    return u / max(_norm(u), 1e-12)


def axis_angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(math.acos(max(-1.0, min(1.0, float(a @ b)))))


@dataclass
class HandGuide:
    """Push the handle until the scope axis is within ``tolerance_deg`` of ``target_axis``."""

    target_axis: np.ndarray
    grip_force: float
    max_force: float = 12.0
    gain: float = 60.0  # N per rad of remaining angle
    integral_gain: float = 25.0  # N per rad s
    tolerance_deg: float = 1.0
    twist_torque: float = 0.0  # N m about the shaft, optional
    max_speed: float | None = None  # rad/s; speed-driven hand when set
    force_rate: float = 300.0  # N per (rad/s) of speed error per second (speed-driven hand)
    engaged: bool = True
    done_time: float | None = None
    _integral: float = field(default=0.0, repr=False)
    _force: float = field(default=0.0, repr=False)
    _prev_angle: float | None = field(default=None, repr=False)
    _speed: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        self.target_axis = np.asarray(self.target_axis, float) / np.linalg.norm(self.target_axis)
        if self.grip_force < 0 or self.max_force <= 0:
            raise ValueError("grip_force must be >= 0 and max_force > 0")

    def remaining(self, world: SimWorld) -> float:
        _, d = world.shaft_axis()
        return axis_angle(d, self.target_axis)

    def apply(self, world: SimWorld, t: float, dt: float) -> float:
        """Set the hand wrench on the world; returns the grip force (0 once released)."""
        if not self.engaged:
            world.set_hand_wrench()
            return 0.0
        _, d = world.shaft_axis()
        angle = axis_angle(d, self.target_axis)
        if angle < math.radians(self.tolerance_deg):
            self.engaged = False
            self.done_time = t
            world.set_hand_wrench()
            return 0.0
        toward = across_shaft(self.target_axis, d)  # where the tip must go
        if self.max_speed is None:
            self._integral += angle * dt
            magnitude = min(self.max_force, self.gain * angle + self.integral_gain * self._integral)
        else:
            if self._prev_angle is not None:
                rate = (self._prev_angle - angle) / dt
                self._speed += (rate - self._speed) * min(1.0, dt / 0.05)  # 50 ms perception lag
            self._prev_angle = angle
            wanted = min(self.max_speed, 2.0 * angle)
            self._force = _clip(self._force + self.force_rate * (wanted - self._speed) * dt, 0.0, self.max_force)
            magnitude = self._force
        force = -magnitude * toward  # the handle sits behind the pivot: push it the other way
        world.set_hand_wrench(force=force, torque=self.twist_torque * d)
        return self.grip_force


def rotate_axis(axis: np.ndarray, about: Sequence[float] | np.ndarray, angle_deg: float) -> np.ndarray:
    """``axis`` rotated by ``angle_deg`` about ``about`` (Rodrigues)."""
    k = np.asarray(about, float) / np.linalg.norm(about)
    a = math.radians(angle_deg)
    v = np.asarray(axis, float)
    return v * math.cos(a) + np.cross(k, v) * math.sin(a) + k * (k @ v) * (1 - math.cos(a))


@dataclass
class InstrumentPath:
    """An instrument tip gliding over the tissue: waypoints (x, y) relative to ``origin``, visited
    with smooth (cosine) interpolation at ``speed`` m/s, plus a small tremor-free wiggle."""

    origin: np.ndarray
    waypoints: list[tuple[float, float]]
    speed: float = 0.01
    wiggle: float = 0.003
    wiggle_hz: float = 0.7
    _times: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pts = np.asarray(self.waypoints, float)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        self._times = np.concatenate([[0.0], np.cumsum(seg / self.speed)])

    def tip(self, t: float) -> np.ndarray:
        pts = np.asarray(self.waypoints, float)
        i = int(np.searchsorted(self._times, t, side="right")) - 1
        if i >= len(pts) - 1:
            xy = pts[-1]
        else:
            s = (t - self._times[i]) / (self._times[i + 1] - self._times[i])
            s = 0.5 - 0.5 * math.cos(math.pi * s)
            xy = pts[i] + s * (pts[i + 1] - pts[i])
        w = self.wiggle * math.sin(2 * math.pi * self.wiggle_hz * t)
        return np.asarray(self.origin, float) + np.array([xy[0] + w, xy[1] + 0.5 * w, 0.0])


@dataclass(frozen=True)
class HousingDisturbance:
    """A sustained lateral load on the phantom housing from ``start`` on (Fig. 5: t = 3.6 s)."""

    start: float = 3.6
    shift: tuple[float, float] = (0.0, 0.01)

    def apply(self, world: SimWorld, t: float) -> None:
        load = world.housing_load_for_shift(np.array(self.shift)) if t >= self.start else np.zeros(3)
        world.set_housing_load(load)


@dataclass
class SpeedDrivenHand:
    """A hand that tries to pivot the scope at ``speed`` (rad/s) toward ``direction``.

    The push on the handle aims at ``gain`` (N per rad/s) times the shortfall of the shaft's
    angular speed below ``speed``, capped at ``max_force`` (N); the hand perceives the speed with a
    ``lag`` (s) first-order delay and changes its push at most at ``force_rate`` (N/s), also when it
    lets go. It grips with ``grip_force`` (N) until its push is back to zero, and lets go once the
    shaft has turned ``sweep_deg`` from its axis at the first call (or when ``engaged`` is cleared).
    """

    direction: np.ndarray  # where the tip should go (base frame; its part ⟂ the shaft is used)
    speed: float  # rad/s
    grip_force: float  # N
    gain: float = 60.0  # N per rad/s of speed shortfall
    max_force: float = 30.0  # N
    force_rate: float = 600.0  # N/s: 30 N in 50 ms
    sweep_deg: float = 30.0  # deg of turn after which the hand lets go
    lag: float = 0.05  # s
    engaged: bool = True
    _d0: np.ndarray | None = field(default=None, repr=False)
    _prev: np.ndarray | None = field(default=None, repr=False)
    _speed: float = field(default=0.0, repr=False)
    _force: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        self.direction = np.asarray(self.direction, float) / np.linalg.norm(self.direction)
        if self.speed <= 0 or self.max_force <= 0 or self.force_rate <= 0 or self.grip_force < 0:
            raise ValueError("speed, max_force and force_rate must be > 0, grip_force >= 0")

    def apply(self, world: SimWorld, t: float, dt: float) -> float:
        """Set the hand wrench on the world; returns the grip force (0 once released)."""
        _, d = world.shaft_axis()
        if self._d0 is None:
            self._d0 = d
        if self._prev is not None:
            rate = _norm(d - self._prev) / dt
            self._speed += (rate - self._speed) * min(1.0, dt / self.lag)
        self._prev = d
        if self.engaged and axis_angle(d, self._d0) >= math.radians(self.sweep_deg):
            self.engaged = False
        wanted = _clip(self.gain * (self.speed - self._speed), 0.0, self.max_force) if self.engaged else 0.0
        step = self.force_rate * dt
        self._force += _clip(wanted - self._force, -step, step)
        if not self.engaged and self._force <= 0.0:
            world.set_hand_wrench()
            return 0.0
        toward = across_shaft(self.direction, d)
        world.set_hand_wrench(force=-self._force * toward)  # handle behind the pivot
        return self.grip_force
