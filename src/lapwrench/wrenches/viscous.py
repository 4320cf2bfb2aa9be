"""The viscous resistance wrench W_f (eq 40)."""

from __future__ import annotations

import numpy as np

from lapwrench.spatial import Mat, Wrench
from lapwrench.wrenches.base import Cue, TickContext
from lapwrench.wrenches.interaction import grip_gain


class ViscousCue(Cue):
    """Eq (40): W_f = [-k_t φ̇_G; -k_f ṗ_G] about p_G, with [φ̇_G; ṗ_G] = J_G θ̇.

    The paper writes the components on the {G} axes; the sum is the same vector in {B}, so
    W_f = -D_f J_G θ̇ with D_f = diag(k_t I3, k_f I3).

    One table cannot serve both cues (README, "damping"): the printed k_t = 150 N m s gives the
    hand the speeds of the paper's Fig. 4 but turns the view at ~0.2°/s under the 10 N tracking
    force. So k_t applies while the surgeon grips the handle (δ > 0, eq 7) and ``k_t_unguided``
    otherwise, when only the autonomous cues move the scope.

    Parameters: the ``viscous:`` section; the grip is read with the ``interaction:`` section's.
    """

    inputs = ("tactile",)
    config_section = "viscous"
    fused = True

    def damping_matrix(self, ctx: TickContext) -> Mat:
        v, grip = self.params, self.cfg.interaction
        tactile = ctx.inputs.tactile
        gripped = tactile is not None and grip_gain(
            tactile.values, grip.k_H, grip.k_min, float(grip.contact_threshold)
        )[0] > 0.0
        return np.diag([v.k_t if gripped else v.k_t_unguided] * 3 + [v.k_f] * 3).astype(float)

    def compute(self, ctx: TickContext) -> Wrench:
        w = -self.damping_matrix(ctx) @ (ctx.geometry.J_G @ ctx.kin.dq)
        return Wrench(w[:3], w[3:], ctx.geometry.p_G)
