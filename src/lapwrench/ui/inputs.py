"""The page's values, validated, and the hand they stand for.

Everything a browser sends is untrusted: a slider can deliver NaN, a number box any float, a
dropdown an unknown choice. Each value passes through :func:`checked_number` or
:func:`checked_choice` first; a bad one raises :class:`UiInputError`, whose message the page shows.

The hand: a grip force (N) from a named level or from a wanted grip gain δ, a push on the handle
across the shaft (direction about the shaft, magnitude), a torque about the shaft, and the pull of
the draggable handle gizmo (a spring: force proportional to how far it is dragged, capped). Like the
push, the gizmo's pull acts across the shaft only: its part along the shaft would push the scope in
or out through the trocar (the wall then drags the incision), which the paper's hand-guiding never
does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lapwrench.sim.sensors import GripModel

# Grip forces (N) of the named levels: the paper's Fig. 4 levels, δ ≈ 0.3, 1.1, 2.0 with k_H = 2000
# (lapwrench.sim.sensors.GripModel).
GRIP_LEVELS: dict[str, float] = {"none": 0.0, "low": 5.0, "medium": 17.0, "high": 30.0}
MAX_GRIP_FORCE = 60.0  # N, a firm one-hand grip
MAX_DELTA = 4.0  # largest δ the page asks for (30 N gives 2.0)
MAX_HAND_FORCE = 30.0  # N, the largest push on the handle, from the sliders or the gizmo
MAX_HAND_TORQUE = 1.0  # N m about the shaft
GIZMO_STIFFNESS = 300.0  # N/m: the gizmo pulls 3 N per cm of drag, MAX_HAND_FORCE at 10 cm


class UiInputError(ValueError):
    """A value from the page that cannot be used; the message is shown on the page."""


def checked_number(value: object, name: str, lo: float, hi: float) -> float:
    """``value`` as a float in ``[lo, hi]``; :class:`UiInputError` naming ``name`` otherwise
    (not a number, NaN, infinite, out of range)."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise UiInputError(f"{name}: not a number ({str(value)[:40]!r})")
    x = float(value)
    if not math.isfinite(x):
        raise UiInputError(f"{name}: must be a finite number, got {x}")
    if not lo <= x <= hi:
        raise UiInputError(f"{name}: must lie in [{lo:g}, {hi:g}], got {x:g}")
    return x


def checked_choice(value: object, name: str, choices: Sequence[str]) -> str:
    """``value`` if it is one of ``choices``; :class:`UiInputError` otherwise."""
    if not isinstance(value, str) or value not in choices:
        raise UiInputError(f"{name}: unknown choice {str(value)[:40]!r} (one of {', '.join(choices)})")
    return value


def grip_force_for_delta(delta: float, k_H: float, model: GripModel | None = None) -> float:
    """Grip force (N) whose tactile reading gives the grip gain ``delta``: eq (7) δ = ΣS_e / k_H with
    the simulated handle's ΣS_e ≈ counts_per_newton x F (:class:`~lapwrench.sim.sensors.GripModel`)."""
    m = model or GripModel()
    return float(delta) * float(k_H) / m.counts_per_newton


def perpendicular_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across the shaft direction ``d`` (a unit vector): e1 toward the base x axis
    (or y when the shaft is along x), e2 = d x e1. Azimuth 0° pushes along e1, 90° along e2.
    Plain float arithmetic: the session calls it every tick while the hand pushes."""
    dx, dy, dz = (float(v) for v in d)
    rx, ry = (1.0, 0.0) if abs(dx) < 0.9 else (0.0, 1.0)
    k = rx * dx + ry * dy
    ax, ay, az = rx - k * dx, ry - k * dy, -k * dz
    n = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / n, ay / n, az / n
    return np.array([ax, ay, az]), np.array([dy * az - dz * ay, dz * ax - dx * az, dx * ay - dy * ax])


def across_shaft(f: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The part of force ``f`` across the shaft direction ``d`` (a unit vector): f - (f . d) d."""
    return f - float(f @ d) * d


def push_force(d: np.ndarray, azimuth_deg: float, magnitude: float) -> np.ndarray:
    """The push (N, {B}) across the shaft ``d``: ``magnitude`` at ``azimuth_deg`` about the shaft."""
    e1, e2 = perpendicular_basis(d)
    a = math.radians(azimuth_deg)
    return magnitude * (math.cos(a) * e1 + math.sin(a) * e2)


def gizmo_force(drag: np.ndarray, stiffness: float = GIZMO_STIFFNESS, cap: float = MAX_HAND_FORCE) -> np.ndarray:
    """The handle gizmo's pull (N): ``stiffness`` x the drag (m, gizmo minus handle), at most ``cap``."""
    f = stiffness * np.asarray(drag, float)
    n = float(np.linalg.norm(f))
    if not math.isfinite(n):
        return np.zeros(3)
    return f if n <= cap else f * (cap / n)


@dataclass
class HandInput:
    """What the page asks the hand to do; the session applies it every tick.

    Attributes:
        grip_force: N on the tactile handle (0: not gripped).
        push_azimuth_deg: direction of the push about the shaft (see :func:`perpendicular_basis`).
        push_magnitude: N across the shaft.
        twist_torque: N m about the shaft (positive: right-handed about the shaft direction).
        gizmo: N, the handle gizmo's spring pull (:func:`gizmo_force`) while it is dragged; the
            hand applies its part across the shaft (:func:`across_shaft`), as the push.
    """

    grip_force: float = 0.0
    push_azimuth_deg: float = 0.0
    push_magnitude: float = 0.0
    twist_torque: float = 0.0
    gizmo: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def wrench(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(force N, torque N m) on the handle in {B} for the shaft direction ``d`` (a unit vector):
        the push and the gizmo's pull, both across the shaft, the total capped at
        :data:`MAX_HAND_FORCE`."""
        f = push_force(d, self.push_azimuth_deg, self.push_magnitude) + across_shaft(self.gizmo, d)
        n = float(np.linalg.norm(f))
        if n > MAX_HAND_FORCE:
            f = f * (MAX_HAND_FORCE / n)
        return f, self.twist_torque * d

    def key(self) -> tuple[float, float, float, float, bytes]:
        """What the hand asks, as a value: equal keys give the same :meth:`wrench` for the same shaft."""
        return (self.grip_force, self.push_azimuth_deg, self.push_magnitude, self.twist_torque,
                np.asarray(self.gizmo, float).tobytes())

    def set_grip_level(self, level: object) -> None:
        self.grip_force = GRIP_LEVELS[checked_choice(level, "grip", tuple(GRIP_LEVELS))]

    def set_grip_delta(self, delta: object, k_H: float) -> None:
        self.grip_force = grip_force_for_delta(checked_number(delta, "grip δ", 0.0, MAX_DELTA), k_H)

    def set_push(self, azimuth_deg: object, magnitude: object) -> None:
        """Push ``magnitude`` N at ``azimuth_deg``; a bad value of either lets go of the push (else a bad
        direction left on the page would keep the last push on, however the magnitude is lowered)."""
        try:
            a = checked_number(azimuth_deg, "push direction (deg)", -360.0, 360.0)
            m = checked_number(magnitude, "push magnitude (N)", 0.0, MAX_HAND_FORCE)
        except UiInputError:
            self.push_magnitude = 0.0
            raise
        self.push_azimuth_deg, self.push_magnitude = a, m

    def set_twist(self, torque: object) -> None:
        self.twist_torque = checked_number(torque, "torque about the shaft (N m)", -MAX_HAND_TORQUE, MAX_HAND_TORQUE)

    def set_gizmo(self, drag: object) -> None:
        """Set the gizmo's pull from its drag (m, 3 numbers); a bad drag releases it."""
        v = np.asarray(drag, dtype=float).reshape(-1) if _is_vector(drag) else np.zeros(0)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            self.gizmo = np.zeros(3)
            raise UiInputError(f"handle gizmo: a drag must be 3 finite numbers, got {str(drag)[:60]}")
        self.gizmo = gizmo_force(v)

    def release(self) -> None:
        """Hand off: no grip, no push, no torque."""
        self.grip_force = self.push_magnitude = self.twist_torque = 0.0
        self.gizmo = np.zeros(3)


class HandWrenchCache:
    """The hand's wrench (:meth:`HandInput.wrench`) for the shaft direction, recomputed only when the
    hand changed (:meth:`HandInput.key`), the world is another one, or the shaft turned by more than
    ``turn`` (unit-vector change; 1e-3 ≈ 0.06° leaves at most 0.1 % of the force along the shaft):
    the session asks for it every tick, and the hand seldom changes between two."""

    def __init__(self, turn: float = 1e-3) -> None:
        self.turn = turn
        self._key: tuple | None = None
        self._world: object = None
        self._d = np.zeros(3)
        self._wrench = (np.zeros(3), np.zeros(3))
        self.hand_changed = False  # the last call saw a hand other than the call before (not just the shaft)

    def wrench(self, hand: HandInput, d: np.ndarray, world: object = None) -> tuple[np.ndarray, np.ndarray, bool]:
        """(force N, torque N m, whether it was recomputed) for shaft direction ``d`` in ``world``."""
        key = hand.key()
        self.hand_changed = key != self._key
        changed = self.hand_changed or world is not self._world or float(np.max(np.abs(d - self._d))) > self.turn
        if changed:
            self._key, self._world, self._d = key, world, np.array(d, float)
            self._wrench = hand.wrench(self._d)
        return self._wrench[0], self._wrench[1], changed


def _is_vector(value: object) -> bool:
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return True
