"""The RCM constraint wrench W_r (eq 13-14), the task-space wrench."""

from __future__ import annotations

import numpy as np

from lapwrench.config import RcmConfig
from lapwrench.jit import kernel
from lapwrench.spatial import Vec, Wrench
from lapwrench.wrenches.base import TickContext


@kernel
def rcm_force(e_R: Vec, e_R_rate: Vec, Kp: float, Kd: float) -> Vec:
    """Eq (14): F_r = -K_p e_R - K_d ė_R, with K_p = Kp I3 and K_d = Kd I3."""
    return -Kp * e_R - Kd * e_R_rate


class RcmWrench:
    """Eq (13): W_r = [0; F_r], applied through J_R in the task space (eq 2)."""

    name = "rcm"

    def __init__(self, cfg: RcmConfig) -> None:
        self.cfg = cfg

    def compute(self, ctx: TickContext) -> Wrench:
        g = ctx.geometry
        # e_R at the reference plus what the measured pose adds (motion/measured_feedback.py)
        return Wrench(np.zeros(3), rcm_force(g.e_R + g.e_R_offset, g.e_R_rate, self.cfg.Kp, self.cfg.Kd), g.p_R)
