"""The RCM constraint wrench W_r (eq 13-14), the task-space wrench, and the optional feed-forward that
cancels the velocity-product terms eq (2) leaves in the RCM error's dynamics (``rcm.feedforward``)."""

from __future__ import annotations

import numpy as np

from lapwrench.allocation import weighted_pseudo_inverse
from lapwrench.jit import kernel_inlined
from lapwrench.rcm.geometry import lateral_rcm_jacobian, rcm_error_drift
from lapwrench.robot.model import Kinematics, inverse_inertia
from lapwrench.spatial import Mat, Vec, Wrench, matvec, matvec_into
from lapwrench.wrenches.base import Cue, TickContext


@kernel_inlined
def rcm_force(e_R: Vec, e_R_rate: Vec, Kp: float, Kd: float) -> Vec:
    """Eq (14): F_r = -K_p e_R - K_d ė_R, with K_p = Kp I3 and K_d = Kd I3."""
    F = np.empty(3)
    for i in range(3):
        F[i] = -Kp * e_R[i] - Kd * e_R_rate[i]
    return F


@kernel_inlined
def rcm_feedforward(kin: Kinematics, Minv: Mat, J_lat: Mat, J_lat_pinv: Mat, drift: Vec) -> Vec:
    """F_ff = -Λ_R (μ - J_R M⁻¹ C θ̇) at p_R: the force that cancels the velocity-product terms of the
    RCM error's acceleration (a departure from eq 2, which has none; ``rcm.feedforward: false`` is the paper's).

    With the model M θ̈ + C θ̇ = τ (eq 1, gravity compensated) and τ from eq (2), the dynamically
    consistent null space drops out of J_R θ̈ and

        ë_R = Λ_R⁻¹ F_r + μ - J_R M⁻¹ C θ̇,    Λ_R = (J_R M⁻¹ J_Rᵀ)⁻¹,

    μ the drift :func:`~lapwrench.rcm.geometry.rcm_error_drift`. Without F_ff the RCM error is a
    spring-damper (eq 14) driven by these terms, which grow with θ̇² and with Λ_R near a singularity.

    Only the part across the shaft is cancelled, with the lateral task ``J_lat`` = P J_R
    (:func:`~lapwrench.rcm.geometry.lateral_rcm_jacobian`) and its exact pseudo-inverse ``J_lat_pinv``
    (eq 4 with the null direction d_z), in either form of the task: e_R ⟂ d_z always, so its
    acceleration along d_z is set by the geometry, and the printed J_R's Λ_R has an eigenvalue of
    about 1/|e_R|² there (cancelling it asked for 1e8 N at |e_R| = 10 µm). Λ_R is taken as
    J⁺ᵀ M J⁺ (= Λ_R Λ_R⁻¹ Λ_R); F_ff ⟂ d_z, so J_Rᵀ F_ff is the same for the printed J_R.
    """
    n = kin.q.shape[0]
    c = np.empty(n)
    for i in range(n):
        c[i] = kin.nle[i] - kin.gravity[i]  # C θ̇
    Minv_c = matvec(Minv, c)
    mu = matvec(J_lat, Minv_c)
    for i in range(mu.shape[0]):
        mu[i] = drift[i] - mu[i]  # μ
    # -J⁺ᵀ M J⁺ μ, the products' vectors written into the two n-vectors no longer needed (c, M⁻¹ c)
    matvec_into(J_lat_pinv, mu, c)
    matvec_into(kin.M, c, Minv_c)
    F = matvec(J_lat_pinv.T, Minv_c)
    for i in range(F.shape[0]):
        F[i] = -F[i]
    return F


class RcmCue(Cue):
    """Eq (13): W_r = [0; F_r] about p_R, applied through J_R in the task space (eq 2).

    Parameters: the ``rcm:`` section (K_p, K_d, ``feedforward``: F_r plus :func:`rcm_feedforward`). The
    primary task: it cannot be switched off.
    """

    priority = "task"
    config_section = "rcm"
    fused = True

    def compute(self, ctx: TickContext) -> Wrench:
        g = ctx.geometry
        # e_R at the reference plus what the measured pose adds (motion/measured_feedback.py)
        F = rcm_force(g.e_R + g.e_R_offset, g.e_R_rate, self.params.Kp, self.params.Kd)
        if self.params.feedforward:
            kin = ctx.kin
            Minv = inverse_inertia(kin.M)
            J_lat = lateral_rcm_jacobian(kin, g.p_R)  # across the shaft only, as the tick (rcm_feedforward)
            J_lat_pinv = weighted_pseudo_inverse(J_lat, Minv, kin.d_z)
            F = F + rcm_feedforward(kin, Minv, J_lat, J_lat_pinv, rcm_error_drift(kin, g.p_R, g.rcm_velocity))
        return Wrench(np.zeros(3), F, g.p_R)
