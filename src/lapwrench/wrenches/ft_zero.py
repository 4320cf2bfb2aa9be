"""The handle F/T's zero, kept while nobody touches the grip (not in the paper).

The sensor is tared once, untouched, where the run starts. What is left of its bias after that (the
tare's own average of noisy samples, then the drift of a strain-gauge sensor with temperature and
time) reads as a steady push: gripped without pushing, eq (6) turns it into motion (in the
simulation a 0.02 N tare residual crept the scope at about 0.1 mm/s). The tactile array says when
nobody touches the grip: every element at or below the contact threshold. Then the hand's true
wrench is zero, and what the sensor still reads (after the grip's weight,
:mod:`lapwrench.wrenches.grip_weight`) is bias. So while untouched the zero b follows the reading
with time constant T:

    b ← b + (Δt / T) (w - b)    if nobody touches the grip and |w_F - b_F| ≤ BAND_FORCE,
                                 |w_τ - b_τ| ≤ BAND_TORQUE;   then |b_F| ≤ MAX_FORCE, |b_τ| ≤ MAX_TORQUE

and the controller uses w - b (w = [force; torque] in {H}). The band keeps a real push out of b even
if the tactile array misses a touch (a drift is slow; a push is not), and the bound keeps a fault
from ever moving the zero far from the tare. Gripped, b holds.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.spatial import Mat, Vec
from lapwrench.wrenches.grip_weight import without_grip_weight
from lapwrench.wrenches.interaction import contact_count


class FtTare(NamedTuple):
    """Where the handle F/T was tared, and its zero since: the state :func:`conditioned_ft` reads and steps."""

    R_H0: Mat  # {H}'s rotation in {B} where the F/T was tared untouched (lapwrench.wrenches.grip_weight)
    zero: Vec  # the zero b = [b_F; b_τ] in {H} (module docstring), stepped in place; zero at the tare

    @staticmethod
    def at(R_H0: Mat) -> FtTare:
        return FtTare(np.array(R_H0, dtype=np.float64, order="C"), np.zeros(6))  # its own copy


def zero_gain(dt: float, zero_time: float) -> float:
    """Δt / T of :func:`zero_step`, at most 1; 0 (the zero held) for ``zero_time`` 0."""
    return 0.0 if zero_time <= 0.0 else min(1.0, dt / zero_time)


BAND_FORCE = 1.0  # N: a reading further than this from the zero is not bias (a push the tactile array missed)
BAND_TORQUE = 0.05  # N m: the same for the torque (1 N at a 5 cm lever)
MAX_FORCE = 3.0  # N: the zero never moves further than this from the tare
MAX_TORQUE = 0.15  # N m


@kernel
def untouched(tactile: Vec, has_tactile: bool, contact_threshold: float) -> bool:
    """Nobody touches the grip: a tactile reading with every element at or below the contact threshold (the
    paper's no-contact value is 0). Without a tactile reading nobody can tell: False."""
    return has_tactile and contact_count(tactile, contact_threshold) == 0


@kernel
def _clip_norm(v: Vec, limit: float) -> None:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n > limit:
        for i in range(3):
            v[i] *= limit / n


@kernel
def zero_step(zero: Vec, force: Vec, torque: Vec, gain: float) -> bool:
    """One step of the zero b (``zero``: [b_F; b_τ], in place) toward the untouched reading (module
    docstring), ``gain`` = Δt / T; returns whether it moved (False when the reading left the band)."""
    dF = force - zero[:3]
    dT = torque - zero[3:]
    if math.sqrt(dF @ dF) > BAND_FORCE or math.sqrt(dT @ dT) > BAND_TORQUE:
        return False
    zero[:3] += gain * dF
    zero[3:] += gain * dT
    _clip_norm(zero[:3], MAX_FORCE)
    _clip_norm(zero[3:], MAX_TORQUE)
    return True


@kernel_inlined
def conditioned_ft(
    force: Vec, torque: Vec, R_H: Mat, R_H0: Mat, grip_mass: float, grip_com: Vec, zero: Vec, gain: float,
    tactile: Vec, has_tactile: bool, contact_threshold: float,
) -> tuple[Vec, Vec]:
    """The hand's wrench in {H} from a tared F/T reading: the grip's weight taken off
    (:func:`~lapwrench.wrenches.grip_weight.without_grip_weight`, when ``grip_mass`` > 0), the zero
    stepped while nobody touches the grip (:func:`zero_step`, when ``gain`` > 0) and taken off. New arrays."""
    if grip_mass > 0.0:
        force, torque = without_grip_weight(force, torque, R_H, R_H0, grip_mass, grip_com)
    if gain > 0.0 and untouched(tactile, has_tactile, contact_threshold):
        zero_step(zero, force, torque, gain)
    return force - zero[:3], torque - zero[3:]
