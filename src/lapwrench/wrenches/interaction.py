"""The interaction wrench W_h from the handle F/T sensor, gated by the tactile grip array (eq 5-7)."""

from __future__ import annotations

import numpy as np

from lapwrench.config import InteractionConfig
from lapwrench.jit import kernel
from lapwrench.spatial import Mat, Vec, Wrench
from lapwrench.wrenches.base import TickContext


@kernel
def surgeon_wrench(force_H: Vec, torque_H: Vec, R_H: Mat) -> tuple[Vec, Vec]:
    """Eq (5): W_s = [M_s; F_s] with the sensor components on the {H} axes, returned in {B}."""
    return R_H @ torque_H, R_H @ force_H


@kernel
def grip_gain(values: Vec, k_H: float, k_min: int, contact_threshold: float = 0.0) -> tuple[float, int]:
    """Eq (7): δ = Σ Se_j / k_H if n_c > k_min else 0; returns (δ, n_c).

    An element counts as contacted when its value exceeds ``contact_threshold`` (the paper's
    nominal no-contact value is 0).
    """
    n_c = 0
    for x in values:
        n_c += x > contact_threshold
    if n_c <= k_min:
        return 0.0, n_c
    return np.sum(values) / k_H, n_c


@kernel
def interaction_wrench(force_H: Vec, torque_H: Vec, R_H: Mat, delta: float) -> tuple[Vec, Vec]:
    """Eq (6): W_h = δ [M_s^z z_H; F_s^x x_H + F_s^y y_H + F_s^z z_H] in {B}.

    Only the axial torque and the three forces are kept: under the RCM the scope has four DOFs.
    """
    moment = delta * torque_H[2] * np.ascontiguousarray(R_H[:, 2])
    force = delta * (R_H @ force_H)
    return moment, force


class InteractionWrench:
    """W_h about the handle point p_H; zero when the F/T or tactile reading is missing."""

    name = "interaction"

    def __init__(self, cfg: InteractionConfig) -> None:
        self.cfg = cfg
        self.delta = 0.0
        self.contacts = 0

    def compute(self, ctx: TickContext) -> Wrench:
        kin, ft, tactile = ctx.kin, ctx.inputs.ft, ctx.inputs.tactile
        if tactile is None:
            self.delta, self.contacts = 0.0, 0
        else:
            self.delta, self.contacts = grip_gain(
                tactile.values, self.cfg.k_H, self.cfg.k_min, self.cfg.contact_threshold
            )
        if ft is None or self.delta == 0.0:
            return Wrench.zero(kin.p_H)
        moment, force = interaction_wrench(ft.force, ft.torque, kin.R_H, self.delta)
        return Wrench(moment, force, kin.p_H)
