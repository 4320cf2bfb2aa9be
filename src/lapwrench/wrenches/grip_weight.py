"""The grip's weight in the handle F/T reading, and taking it off (not in the paper).

The surgeon holds a grip that hangs beyond the F/T sensor (``scope.grip_mass`` at ``scope.grip_com``
in {H}), so the sensor reads the grip's weight on top of the hand. With g = (0, 0, -9.81) m/s² in
{B} and R_H the rotation of {H} in {B}, an untouched grip reads

    F_w = m R_Hᵀ g,    τ_w = c × F_w        (in {H}, τ about the sensor's origin)

as if a hand pressed on it. The F/T is tared with the handle untouched at the pose the controller
starts from (R_H0), which takes off F_w(R_H0) along with the sensor's bias; what is left when the
scope has turned to R_H is the change

    ΔF = m (R_Hᵀ - R_H0ᵀ) g,    Δτ = c × ΔF,

which eq (5) would read as the surgeon's push: gripped (δ > 0) the scope would drift by itself,
faster the further it has tilted from where it was tared (0.1 kg tilted 30° is 0.5 N). The
controller subtracts it (:func:`without_grip_weight`) with R_H at the *measured* joints before any
cue or eq (19) reads the F/T. The grip's inertia (m a, under 0.02 N at the scope's accelerations)
is left in.
"""

from __future__ import annotations

import numpy as np

from lapwrench.jit import kernel
from lapwrench.spatial import Mat, Vec, cross3

GRAVITY_B = np.array([0.0, 0.0, -9.81])  # m/s², in {B} (z up)


@kernel
def grip_weight_change(R_H: Mat, R_H0: Mat, mass: float, com: Vec) -> tuple[Vec, Vec]:
    """(ΔF, Δτ) in {H}: what the grip's weight adds to an F/T reading tared at R_H0, now at R_H (module
    docstring)."""
    dF = np.empty(3)
    for i in range(3):  # (R_Hᵀ - R_H0ᵀ) g: column i of each rotation against g
        s = 0.0
        for k in range(3):
            s += (R_H[k, i] - R_H0[k, i]) * GRAVITY_B[k]
        dF[i] = mass * s
    return dF, cross3(com, dF)


@kernel
def without_grip_weight(
    force: Vec, torque: Vec, R_H: Mat, R_H0: Mat, mass: float, com: Vec
) -> tuple[Vec, Vec]:
    """The hand's force and torque in {H}: the reading (tared at R_H0) minus :func:`grip_weight_change`
    at R_H; new arrays."""
    dF, dT = grip_weight_change(R_H, R_H0, mass, com)
    return force - dF, torque - dT
