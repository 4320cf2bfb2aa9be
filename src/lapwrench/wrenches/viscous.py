"""The viscous resistance wrench W_f (eq 40)."""

from __future__ import annotations

import numpy as np

from lapwrench.config import ViscousConfig
from lapwrench.spatial import Mat, Wrench
from lapwrench.wrenches.base import TickContext


class ViscousWrench:
    """Eq (40): W_f = [-k_t φ̇_G; -k_f ṗ_G] about p_G, with [φ̇_G; ṗ_G] = J_G θ̇.

    The paper writes the components on the {G} axes; the sum is the same vector in {B}, so
    W_f = -D_f J_G θ̇ with D_f = diag(k_t I3, k_f I3).
    """

    name = "viscous"

    def __init__(self, cfg: ViscousConfig) -> None:
        self.D = np.diag([cfg.k_t] * 3 + [cfg.k_f] * 3)

    def damping_matrix(self) -> Mat:
        return self.D

    def compute(self, ctx: TickContext) -> Wrench:
        w = -self.D @ (ctx.geometry.J_G @ ctx.kin.dq)
        return Wrench(w[:3], w[3:], ctx.geometry.p_G)
