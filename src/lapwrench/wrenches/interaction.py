"""The interaction wrench W_h from the handle F/T sensor, gated by the tactile grip array (eq 5-7)."""

from __future__ import annotations

import numpy as np

from lapwrench.jit import kernel, kernel_inlined
from lapwrench.spatial import Mat, Vec, Wrench, matvec
from lapwrench.wrenches.base import Cue, TickContext


@kernel
def surgeon_wrench(force_H: Vec, torque_H: Vec, R_H: Mat) -> tuple[Vec, Vec]:
    """Eq (5): W_s = [M_s; F_s] with the sensor components on the {H} axes, returned in {B}."""
    return matvec(R_H, torque_H), matvec(R_H, force_H)


@kernel
def contact_count(values: Vec, contact_threshold: float = 0.0) -> int:
    """n_c of eq (7): the elements contacted, those whose value exceeds ``contact_threshold`` (the
    paper's nominal no-contact value is 0)."""
    n_c = 0
    for x in values:
        n_c += x > contact_threshold
    return n_c


@kernel_inlined
def grip_gain(values: Vec, k_H: float, k_min: int, contact_threshold: float = 0.0) -> tuple[float, int]:
    """Eq (7): δ = Σ Se_j / k_H if n_c > k_min else 0; returns (δ, n_c), n_c by :func:`contact_count`."""
    n_c = contact_count(values, contact_threshold)
    if n_c <= k_min:
        return 0.0, n_c
    return np.sum(values) / k_H, n_c


@kernel_inlined
def interaction_wrench(force_H: Vec, torque_H: Vec, R_H: Mat, delta: float) -> tuple[Vec, Vec]:
    """Eq (6): W_h = δ [M_s^z z_H; F_s^x x_H + F_s^y y_H + F_s^z z_H] in {B}.

    Only the axial torque and the three forces are kept: under the RCM the scope has four DOFs.
    """
    axial = delta * torque_H[2]
    moment = np.empty(3)
    force = matvec(R_H, force_H)
    for i in range(3):
        moment[i] = axial * R_H[i, 2]
        force[i] = delta * force[i]
    return moment, force


class InteractionCue(Cue):
    """W_h (eq 6) about the handle point p_H; zero when the F/T or tactile reading is missing.

    Parameters: the ``interaction:`` section (k_H, k_min, the contact threshold).
    """

    inputs = ("ft", "tactile")
    config_section = "interaction"
    fused = True
    telemetry_fields = ("delta", "contacts")

    def grip(self, ctx: TickContext) -> tuple[float, int]:
        """This tick's grip gain δ and contact count n_c (eq 7); (0, 0) without a tactile reading."""
        tactile = ctx.inputs.tactile
        if tactile is None:
            return 0.0, 0
        p = self.params
        return grip_gain(tactile.values, p.k_H, p.k_min, float(p.contact_threshold))

    def compute(self, ctx: TickContext) -> Wrench:
        kin, ft = ctx.kin, ctx.inputs.ft
        delta, _ = self.grip(ctx)
        if ft is None or delta == 0.0:
            return Wrench.zero(kin.p_H)
        moment, force = interaction_wrench(ft.force, ft.torque, kin.R_H, delta)
        return Wrench(moment, force, kin.p_H)

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        delta, contacts = self.grip(ctx)
        return delta, float(contacts)
