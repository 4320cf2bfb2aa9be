"""The RCM constraint wrench W_r (eq 13-14), the task-space wrench."""

from __future__ import annotations

import numpy as np

from lapwrench.jit import kernel
from lapwrench.spatial import Vec, Wrench
from lapwrench.wrenches.base import Cue, TickContext


@kernel
def rcm_force(e_R: Vec, e_R_rate: Vec, Kp: float, Kd: float) -> Vec:
    """Eq (14): F_r = -K_p e_R - K_d ė_R, with K_p = Kp I3 and K_d = Kd I3."""
    F = np.empty(3)
    for i in range(3):
        F[i] = -Kp * e_R[i] - Kd * e_R_rate[i]
    return F


class RcmCue(Cue):
    """Eq (13): W_r = [0; F_r] about p_R, applied through J_R in the task space (eq 2).

    Parameters: the ``rcm:`` section (K_p, K_d). The primary task: it cannot be switched off.
    """

    priority = "task"
    config_section = "rcm"
    fused = True

    def compute(self, ctx: TickContext) -> Wrench:
        g = ctx.geometry
        # e_R at the reference plus what the measured pose adds (motion/measured_feedback.py)
        return Wrench(np.zeros(3), rcm_force(g.e_R + g.e_R_offset, g.e_R_rate, self.params.Kp, self.params.Kd), g.p_R)
