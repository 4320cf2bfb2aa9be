"""The configuration the compiled tick reads (:class:`TickParams`), gathered once when the
controller is built: gains, the scaled Franka limits, the envelope and the tracking parameters as
one named tuple of floats and arrays that numba reads as it is."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lapwrench.config import Config
from lapwrench.motion.envelope import EnvelopeParams
from lapwrench.motion.measured_feedback import FEEDBACK_TIME
from lapwrench.motion.virtual_model import Integrator
from lapwrench.robot.limits import JointLimits
from lapwrench.spatial import Mat, Vec
from lapwrench.wrenches.ft_zero import zero_gain
from lapwrench.wrenches.tracking import TrackingParams


class TickParams(NamedTuple):
    """The configuration the compiled tick reads, gathered once when the controller is built."""

    dt: float
    length: float
    Kp: float
    Kd: float
    rcm_feedforward: bool  # rcm.feedforward: cancel the velocity-product terms (wrenches/rcm.py)
    lateral: bool  # motion.rcm_task == "lateral"
    k_H: float
    k_min: int
    contact_threshold: float
    tracking: TrackingParams
    D_guided: Mat  # diag(k_t I3, k_f I3), eq (40), while the handle is gripped
    D_unguided: Mat  # diag(k_t_unguided I3, k_f I3) otherwise
    self_motion_damping: float
    joint_limit_zone: float
    joint_limit_stiffness: float
    stop_time: float
    integrator: Integrator
    q_lo: Vec  # joint position band of the shaper (limits minus the margin)
    q_hi: Vec
    v_max: Vec  # scaled joint limits
    a_max: Vec
    j_max: Vec
    envelope_enabled: bool
    envelope: EnvelopeParams
    feedback_gain: float  # dt / FEEDBACK_TIME of motion/measured_feedback.py
    feedback_cap: float  # m, 2 x safety.max_rcm_error
    cue_interaction: bool  # the paper's cues that run inside the compiled tick (the ``cues:`` section)
    cue_tracking: bool
    cue_viscous: bool
    grip_mass: float  # kg beyond the F/T sensor, 0 for none (lapwrench.wrenches.grip_weight)
    grip_com: Vec  # m, in {H}
    zero_gain: float  # Δt / T of the F/T's zero while untouched, 0 for off (lapwrench.wrenches.ft_zero)

    @staticmethod
    def from_config(cfg: Config, limits: JointLimits) -> TickParams:
        lim = limits.scaled(cfg.robot.limit_fraction)
        v, m, margin = cfg.viscous, cfg.motion, cfg.robot.position_margin
        return TickParams(
            dt=float(cfg.robot.dt),
            length=float(cfg.scope.length),
            Kp=float(cfg.rcm.Kp),
            Kd=float(cfg.rcm.Kd),
            rcm_feedforward=bool(cfg.rcm.feedforward),
            lateral=m.rcm_task == "lateral",
            k_H=float(cfg.interaction.k_H),
            k_min=int(cfg.interaction.k_min),
            contact_threshold=float(cfg.interaction.contact_threshold),
            tracking=TrackingParams.from_config(cfg.camera, cfg.tracking),
            D_guided=np.diag([v.k_t] * 3 + [v.k_f] * 3).astype(float),
            D_unguided=np.diag([v.k_t_unguided] * 3 + [v.k_f] * 3).astype(float),
            self_motion_damping=float(m.self_motion_damping),
            joint_limit_zone=float(m.joint_limit_zone),
            joint_limit_stiffness=float(m.joint_limit_stiffness),
            stop_time=float(m.stop_time),
            integrator=m.integrator,
            q_lo=np.asarray(limits.position_lower + margin, dtype=float),
            q_hi=np.asarray(limits.position_upper - margin, dtype=float),
            v_max=np.asarray(lim.velocity, dtype=float),
            a_max=np.asarray(lim.acceleration, dtype=float),
            j_max=np.asarray(lim.jerk, dtype=float),
            envelope_enabled=bool(cfg.envelope.enabled),
            envelope=EnvelopeParams.from_config(cfg.envelope),
            feedback_gain=float(cfg.robot.dt / max(FEEDBACK_TIME, cfg.robot.dt)),
            feedback_cap=float(2.0 * cfg.safety.max_rcm_error),
            cue_interaction=_fused(cfg, "interaction"),
            cue_tracking=_fused(cfg, "tracking"),
            cue_viscous=_fused(cfg, "viscous"),
            grip_mass=float(cfg.scope.grip_mass),
            grip_com=np.array(cfg.scope.grip_com, dtype=float),
            zero_gain=zero_gain(float(cfg.robot.dt), float(cfg.interaction.auto_zero_time)),
        )


def _fused(cfg: Config, name: str) -> bool:
    """Whether the paper's cue ``name`` runs (in the compiled tick): enabled, and not replaced by a plugin."""
    entry = cfg.cue(name)
    return entry is not None and entry.type == name
