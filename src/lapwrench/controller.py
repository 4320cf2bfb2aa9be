"""The control tick, top-down like the paper's Fig. 3:

sensors → wrenches → task/null-space allocation → integration → limits → command.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from lapwrench.allocation import (
    nullspace_projector,
    nullspace_torque,
    nullspace_wrench,
    task_priority_torque,
    weighted_pseudo_inverse,
)
from lapwrench.config import Config
from lapwrench.motion.envelope import Envelope
from lapwrench.motion.measured_feedback import MeasuredFeedback
from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.motion.saturation import LimitRows, SaturationResult, saturate
from lapwrench.motion.virtual_model import (
    euler_velocity_step,
    joint_limit_torque,
    self_motion_damping,
    self_motion_projector,
)
from lapwrench.rcm.adaptive import AdaptiveRcm, residual_force
from lapwrench.rcm.geometry import (
    closest_point,
    closest_point_jacobian,
    closest_point_parameter,
    initial_rcm_point,
    lateral_rcm_jacobian,
    rcm_error,
    rcm_error_rate,
    rcm_jacobian,
)
from lapwrench.robot.description import ScopeGeometry
from lapwrench.robot.model import Kinematics, RobotModel
from lapwrench.sensors import InputEvent, InputValidator, SensorFrame, ValidInputs
from lapwrench.spatial import Vec
from lapwrench.wrenches import InteractionWrench, RcmWrench, TrackingWrench, ViscousWrench
from lapwrench.wrenches.base import DampingSource, TaskGeometry, TickContext, WrenchSource

MAX_KEPT_EVENTS = 10_000
# Ticks in a row in which the RCM task cannot be kept inside the joint limits before the arm stops
# (a single tick, e.g. a jerk-limited transient, is clipped into the limits and counted).
INFEASIBLE_TICKS_TO_STOP = 10
Mode = Literal["idle", "tracking", "handle", "handle+tracking", "handle-dominant"]


def _norm(v: Vec) -> float:
    return math.sqrt(float(v @ v))


def classify_mode(handle_engaged: bool, tracking_engaged: bool, handle_force: float, tracking_force: float) -> Mode:
    """The paper's modes (Sec. IV-D, Fig. 7): which cues are engaged and which wrench dominates.

    The handle is engaged while the grip gain δ is non-zero; tracking while instruments are
    detected (even inside the dead zone, where W_c = 0). Both engaged: "handle-dominant" once
    |F_h| exceeds |F_c| (the paper's t5), "handle+tracking" before.
    """
    if handle_engaged and tracking_engaged:
        return "handle-dominant" if handle_force > tracking_force else "handle+tracking"
    if handle_engaged:
        return "handle"
    return "tracking" if tracking_engaged else "idle"


@dataclass(frozen=True)
class TickResult:
    time: float
    q_ref: Vec
    dq_ref: Vec
    ddq_ref: Vec
    tau: Vec
    wrenches: dict[str, Vec]
    W_n: Vec
    e_R: Vec
    p_R: Vec
    p_G: Vec
    delta: float
    contacts: int
    mode: Mode
    residual_lateral: Vec
    residual: Vec | None = None  # ΔF (eq 19) in {B}, N; None when the F/T or the force estimate is missing
    limits_active: tuple[str, ...] = ()  # constraints saturated this tick: "joint3", "depth_max", "pivot_speed", ...
    rcm_infeasible: bool = False  # the RCM task could not be kept inside the limits: the controller is stopping
    events: list[InputEvent] = field(default_factory=list)

    @property
    def rcm_error(self) -> float:
        return float(np.linalg.norm(self.e_R))


class Controller:
    """The unified wrench controller (paper Sec. III) producing 1 kHz joint position references."""

    def __init__(
        self,
        cfg: Config,
        model: RobotModel | None = None,
        extra_sources: Sequence[WrenchSource] = (),
    ) -> None:
        self.cfg = cfg
        self.model = model or RobotModel(cfg.robot.kind, ScopeGeometry.from_config(cfg.scope))
        self.dt = cfg.robot.dt
        self.validator = InputValidator(
            cfg.interaction, cfg.camera, self.model.limits, cfg.inputs.max_image_age
        )
        self.interaction = InteractionWrench(cfg.interaction)
        self.tracking = TrackingWrench(cfg.camera, cfg.tracking)
        self.viscous = ViscousWrench(cfg.viscous, engaged=lambda: self.interaction.delta > 0.0)
        self.rcm_wrench = RcmWrench(cfg.rcm)
        self.null_sources: list[WrenchSource] = [self.interaction, self.tracking, self.viscous, *extra_sources]
        self.damping_sources = [s for s in self.null_sources if isinstance(s, DampingSource)]
        self.shaper = ReferenceShaper(
            self.model.limits, self.dt, cfg.robot.limit_fraction, cfg.robot.position_margin
        )
        self.envelope = Envelope(cfg.envelope, cfg.scope.length, self.dt)
        self.feedback = MeasuredFeedback(self.model, cfg.scope.length, self.dt, 2.0 * cfg.safety.max_rcm_error)
        self.ref: ReferenceState | None = None
        self.rcm: AdaptiveRcm | None = None
        self.stopping = False  # latched when the RCM task cannot be kept inside the joint limits
        self.infeasible_ticks = 0
        self.events: deque[InputEvent] = deque(maxlen=MAX_KEPT_EVENTS)
        self.event_counts: Counter[str] = Counter()

    # -- setup --------------------------------------------------------------------------------
    def reset(self, q0: Vec, p_R: Vec | None = None) -> None:
        """Start at rest at ``q0``; the RCM point is eq (18) unless ``p_R`` is given."""
        q0 = np.asarray(q0, dtype=float)
        if q0.shape != (7,) or not np.all(np.isfinite(q0)):
            raise ValueError("initial configuration must be 7 finite joint positions")
        lim = self.model.limits
        if np.any(q0 < lim.position_lower) or np.any(q0 > lim.position_upper):
            raise ValueError("initial configuration is outside the joint limits")
        self.ref = ReferenceState(q0.copy(), np.zeros(7), np.zeros(7))
        kin = self.model.kinematics(q0, np.zeros(7))
        if p_R is None:
            p_R = initial_rcm_point(kin, self.cfg.scope.length, self.cfg.scope.lambda0)
        self.rcm = AdaptiveRcm(self.cfg.adaptive_rcm, np.asarray(p_R, dtype=float))
        self.envelope.reset(kin)
        self.feedback.reset()
        self.stopping = False
        self.infeasible_ticks = 0
        self.events.clear()
        self.event_counts.clear()

    # -- the tick -----------------------------------------------------------------------------
    def tick(self, frame: SensorFrame) -> TickResult:
        if self.ref is None or self.rcm is None:
            raise RuntimeError("call Controller.reset(q0) before tick()")
        # 1. sensors: validate at the edge; kinematics at the reference (the virtual model's state)
        inputs = self.validator.validate(frame)
        self._report(inputs.events)
        kin = self.model.kinematics(self.ref.q, self.ref.dq)
        Minv = self.model.mass_matrix_inverse(kin.q)

        # 2. adaptive RCM point (eq 19-26)
        residual = self._residual(kin, inputs)
        residual_lateral = self.rcm.update(kin.P, residual, self.dt, kin.twist_E)

        # 3. task geometry (eq 27-36), and what the measured pose adds to the RCM error
        e_R = rcm_error(kin, self.rcm.p_R)
        self.feedback.update(None if inputs.robot is None else inputs.robot.q, kin, self.rcm.p_R, e_R)
        geo = self._geometry(kin, e_R)
        ctx = TickContext(frame.time, kin, geo, inputs)

        # 4. wrenches
        W_r = self.rcm_wrench.compute(ctx)
        null_wrenches = [s.compute(ctx) for s in self.null_sources]

        # 5. task/null-space allocation (eq 2-4, 37-38)
        lateral = self.cfg.motion.rcm_task == "lateral"
        J_pinv = weighted_pseudo_inverse(geo.J_R, Minv, kin.d_z if lateral else None)
        N_r = nullspace_projector(geo.J_R, J_pinv)
        W_n = nullspace_wrench(null_wrenches, geo.p_G)
        tau_n = np.zeros(7) if self.stopping else nullspace_torque(geo.J_G, W_n)
        N_E_T = self_motion_projector(kin, Minv)
        B_self = self_motion_damping(kin, N_E_T, self.cfg.motion.self_motion_damping)
        tau_self = N_E_T @ self._joint_limit_push(kin.q) - B_self @ kin.dq
        tau = task_priority_torque(geo.J_R, W_r.force, N_r, tau_n) + tau_self

        # 6. integration of the virtual model
        damping = self._damping(geo, N_r) + B_self
        if not np.all(np.isfinite(tau)):
            self._report([InputEvent(frame.time, "controller", "non-finite torque; braking")])
            tau = np.zeros(7)
        dq_next = euler_velocity_step(kin, tau, damping, self.dt, self.cfg.motion.integrator)

        # 7. limits and envelope met by the lower-priority motion only (motion/saturation.py) → command
        bounds = self.shaper.acceleration_bounds(self.ref)
        sat = self._saturate(kin, geo, Minv, (dq_next - kin.dq) / self.dt, bounds, frame.time)
        self.ref = self.shaper.advance(self.ref, sat.a, bounds)

        wrenches = {"rcm": W_r.vector}
        wrenches.update({s.name: w.vector for s, w in zip(self.null_sources, null_wrenches, strict=True)})
        F_h, F_c = _norm(wrenches["interaction"][3:]), _norm(wrenches["tracking"][3:])
        if _norm(geo.e_R) > self.cfg.inputs.max_rcm_error:
            self._report([InputEvent(frame.time, "rcm", f"RCM error {_norm(geo.e_R) * 1e3:.1f} mm")])
        return TickResult(
            time=frame.time,
            q_ref=self.ref.q,
            dq_ref=self.ref.dq,
            ddq_ref=self.ref.ddq,
            tau=tau,
            wrenches=wrenches,
            W_n=W_n,
            e_R=geo.e_R,
            p_R=self.rcm.p_R.copy(),
            p_G=geo.p_G,
            delta=self.interaction.delta,
            contacts=self.interaction.contacts,
            mode=classify_mode(
                self.interaction.delta > 0.0 and inputs.ft is not None,
                inputs.instruments is not None and len(inputs.instruments.points) > 0,
                F_h,
                F_c,
            ),
            residual_lateral=residual_lateral,
            residual=residual,
            limits_active=tuple(dict.fromkeys(sat.saturated + sat.dropped)),
            rcm_infeasible=self.stopping,
            events=inputs.events,
        )

    # -- pieces of the tick -------------------------------------------------------------------
    def _report(self, events: list[InputEvent]) -> None:
        """Keep the latest events (bounded) and count them all by source."""
        for e in events:
            self.events.append(e)
            self.event_counts[e.source] += 1

    def _joint_limit_push(self, q: Vec) -> Vec:
        """The self-motion's push away from the joint limits (zone measured inside the position margin)."""
        m = self.cfg.motion
        if m.joint_limit_stiffness == 0.0:
            return np.zeros_like(q)
        return joint_limit_torque(q, self.shaper.q_lo, self.shaper.q_hi, m.joint_limit_zone, m.joint_limit_stiffness)

    def _saturate(
        self, kin: Kinematics, geo: TaskGeometry, Minv: np.ndarray, a_d: Vec, bounds: tuple[Vec, Vec], t: float
    ) -> SaturationResult:
        """Joint limits and the envelope met by changing the lower-priority motion only (motion/saturation.py).

        The task is the RCM error's two lateral rates: J = [x_E  y_E]ᵀ J_R (e_R ⟂ d_z, so the third
        row carries nothing). If the task itself cannot stay inside the joint limits for
        ``INFEASIBLE_TICKS_TO_STOP`` ticks in a row (one such tick is clipped into the limits), the
        controller latches :attr:`stopping`: the cues are switched off and the null-space motion is
        braked with time constant ``motion.stop_time`` while the RCM task keeps acting, down to rest.
        """
        J_task = kin.R_E[:, :2].T @ geo.J_R
        if self.stopping:
            a_d = a_d - self._null_brake(J_task, Minv, kin.dq)
        box = LimitRows.joint_box(*bounds, self.shaper.lim.acceleration)
        env = self.envelope.rows(kin, geo.p_R, a_d, self.feedback.depth_offset)  # on the twist of {E}
        if box.admits(a_d) and (env is None or env.admits(kin.J_E @ a_d)):
            sat = SaturationResult(a_d, (), (), True)  # nothing to saturate: the common case
        else:
            rows = box if env is None else LimitRows.stack(box, env.through(kin.J_E))
            sat = saturate(a_d, J_task, kin.M, rows)
        self.infeasible_ticks = 0 if sat.feasible else self.infeasible_ticks + 1
        if self.infeasible_ticks >= INFEASIBLE_TICKS_TO_STOP and not self.stopping:
            self.stopping = True
            self._report([InputEvent(t, "controller", "RCM task cannot be kept inside the joint limits; stopping")])
        return sat

    def _null_brake(self, J_task: np.ndarray, Minv: np.ndarray, dq: Vec) -> Vec:
        """N θ̇ / T_stop with N = I - J⁺ J (J⁺ M-weighted): a deceleration of the null-space motion only."""
        J_pinv = weighted_pseudo_inverse(J_task, Minv)
        return (dq - J_pinv @ (J_task @ dq)) / self.cfg.motion.stop_time

    def _residual(self, kin: Kinematics, inputs: ValidInputs) -> Vec | None:
        """ΔF (eq 19) when both the F/T reading and the robot's force estimate are valid."""
        if inputs.ft is None or inputs.robot is None or inputs.robot.external_force is None:
            return None
        return residual_force(kin.R_H @ inputs.ft.force, inputs.robot.external_force)

    def _geometry(self, kin: Kinematics, e_R: Vec | None = None) -> TaskGeometry:
        """The task geometry at ``kin``; ``e_R`` (eq 27) when the caller has it already."""
        assert self.rcm is not None
        p_R, L = self.rcm.p_R, self.cfg.scope.length
        e_R = rcm_error(kin, p_R) if e_R is None else e_R
        lateral = self.cfg.motion.rcm_task == "lateral"
        J_R = lateral_rcm_jacobian(kin, p_R) if lateral else rcm_jacobian(kin, p_R)
        s_star = closest_point_parameter(kin, p_R, L)
        p_G, o_G = closest_point(kin, s_star, L)
        return TaskGeometry(
            p_R=p_R,
            rcm_velocity=self.rcm.velocity,
            e_R=e_R,
            e_R_rate=rcm_error_rate(kin, J_R, self.rcm.velocity),
            J_R=J_R,
            s_star=s_star,
            p_G=p_G,
            o_G=o_G,
            J_G=closest_point_jacobian(kin, o_G),
            e_R_offset=self.feedback.e_offset,
        )

    def _damping(self, geo: TaskGeometry, N_r: np.ndarray) -> np.ndarray:
        """B = J_Rᵀ K_d J_R + N_rᵀ J_Gᵀ D J_G: the θ̇-Jacobian of -τ from eq (14) and the damping sources."""
        B = self.cfg.rcm.Kd * geo.J_R.T @ geo.J_R
        for s in self.damping_sources:
            B += N_r.T @ (geo.J_G.T @ (s.damping_matrix() @ geo.J_G))
        return B
