"""The adaptive RCM point (eq 19-26).

Sign convention. ``F_s`` is the force the surgeon's hand applies to the scope, measured by the
handle F/T sensor and rotated into {B}. ``F_m`` is the robot's estimate of the *total external
force acting on the end effector* (hand + trocar), in {B}. Then

    ΔF = F_s - F_m = -F_trocar

is the force the scope exerts on the incision wall. If the incision moves by +x, the wall pushes
the scope toward +x, ΔF points to -x, and ṗ_R = -α F_re⊥ moves p_R toward +x: the RCM follows
the incision. (The Franka's ``O_F_ext_hat_K`` must be mapped to this convention by its driver.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import AdaptiveRcmConfig
from lapwrench.shaping import sine_ramp
from lapwrench.spatial import Mat, Vec


def residual_force(F_s: Vec, F_m: Vec) -> Vec:
    """Eq (19), per axis: ΔF = F_s - F_m (both in {B}; see the module docstring for signs)."""
    return F_s - F_m


def dead_zone_saturation(residual: Vec, cfg: AdaptiveRcmConfig) -> Vec:
    """Eqs (20)-(22), per axis: F_re = sgn(ΔF) Φ(|ΔF|), Φ the dead-zone / sine / saturation map."""
    return np.array(
        [
            math.copysign(sine_ramp(abs(x), cfg.gamma1, cfg.gamma2, cfg.F_op, cfg.ramp), x) if x else 0.0
            for x in np.asarray(residual, dtype=float).tolist()
        ]
    )


def lateral_component(P: Mat, F_re: Vec) -> Vec:
    """Eq (23): F_re⊥ = P(θ) F_re, the part of the residual orthogonal to the shaft."""
    return P @ F_re


def rcm_point_rate(F_re_lateral: Vec, p_R: Vec, p_R_anchor: Vec, alpha: float, beta: float) -> Vec:
    """Eq (24): ṗ_R = -α F_re⊥ - β (p_R - p_R*)."""
    return -alpha * F_re_lateral - beta * (p_R - p_R_anchor)


@dataclass
class AdaptiveRcm:
    """The adaptive RCM point p_R and its piecewise-constant anchor p_R* (eq 24-26).

    Each :meth:`update` integrates eq (24) with explicit Euler over ``dt``. The anchor is reset
    to p_R at the instants where ‖ṗ_R‖ <= ε (eq 25-26) and held constant in between. With
    adaptation disabled p_R stays at its initial value.
    """

    cfg: AdaptiveRcmConfig
    p_R: Vec
    p_R_anchor: Vec = field(init=False)
    velocity: Vec = field(init=False)
    anchor_updates: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        self.p_R = np.array(self.p_R, dtype=float)
        self.p_R_anchor = self.p_R.copy()
        self.velocity = np.zeros(3)

    def update(self, P: Mat, residual: Vec | None, dt: float) -> Vec:
        """Advance p_R by one tick; ``residual`` is ΔF (eq 19) or None when it is unavailable.

        Returns the mapped lateral residual F_re⊥ used this tick.
        """
        if not self.cfg.enabled:
            self.velocity = np.zeros(3)
            return np.zeros(3)
        F_lat = np.zeros(3) if residual is None else lateral_component(P, dead_zone_saturation(residual, self.cfg))
        self.velocity = rcm_point_rate(F_lat, self.p_R, self.p_R_anchor, self.cfg.alpha, self.cfg.beta)
        if math.sqrt(self.velocity @ self.velocity) <= self.cfg.epsilon:  # eq (25)
            self.p_R_anchor = self.p_R.copy()  # eq (26)
            self.anchor_updates += 1
        self.p_R = self.p_R + dt * self.velocity
        return F_lat
