"""The viscous resistance wrench W_f (eq 40)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lapwrench.config import ViscousConfig
from lapwrench.spatial import Mat, Wrench
from lapwrench.wrenches.base import TickContext


class ViscousWrench:
    """Eq (40): W_f = [-k_t φ̇_G; -k_f ṗ_G] about p_G, with [φ̇_G; ṗ_G] = J_G θ̇.

    The paper writes the components on the {G} axes; the sum is the same vector in {B}, so
    W_f = -D_f J_G θ̇ with D_f = diag(k_t I3, k_f I3).

    One table cannot serve both cues (README, "damping"): the printed k_t = 150 N m s gives the
    hand the speeds of the paper's Fig. 4 but turns the view at ~0.2°/s under the 10 N tracking
    force. So k_t applies while ``engaged()`` (the surgeon grips the handle, δ > 0) and
    ``k_t_unguided`` otherwise, when only the autonomous cues move the scope.
    """

    name = "viscous"

    def __init__(self, cfg: ViscousConfig, engaged: Callable[[], bool] = lambda: True) -> None:
        self.D_guided = np.diag([cfg.k_t] * 3 + [cfg.k_f] * 3)
        self.D_unguided = np.diag([cfg.k_t_unguided] * 3 + [cfg.k_f] * 3)
        self.engaged = engaged

    def damping_matrix(self) -> Mat:
        return self.D_guided if self.engaged() else self.D_unguided

    def compute(self, ctx: TickContext) -> Wrench:
        w = -self.damping_matrix() @ (ctx.geometry.J_G @ ctx.kin.dq)
        return Wrench(w[:3], w[3:], ctx.geometry.p_G)
