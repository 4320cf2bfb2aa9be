"""The control tick, top-down like the paper's Fig. 3:

sensors → wrenches → task/null-space allocation → integration → limits → command.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple

import numpy as np

from lapwrench.compiled_tick import CompiledTick, StageResult
from lapwrench.config import Config
from lapwrench.config_ranges import ConfigError
from lapwrench.motion.envelope import WALL_NAMES, Envelope
from lapwrench.motion.measured_feedback import MeasuredFeedback
from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState, advance_reference
from lapwrench.motion.saturation import LimitRows, SaturationResult, saturate
from lapwrench.rcm.adaptive import AdaptiveRcm
from lapwrench.rcm.geometry import initial_rcm_point
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import ScopeGeometry
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import (
    ForceTorqueReading,
    InputEvent,
    InputValidator,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.spatial import Mat, Vec
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.base import Cue
from lapwrench.wrenches.ft_zero import FtTare
from lapwrench.wrenches.registry import build_cues, input_specs

MAX_KEPT_EVENTS = 10_000
# Ticks in a row in which the RCM task cannot be kept inside the joint limits before the arm stops
# (a single tick, e.g. a jerk-limited transient, is clipped into the limits and counted).
INFEASIBLE_TICKS_TO_STOP = 10
Mode = Literal["idle", "tracking", "handle", "handle+tracking", "handle-dominant"]
EXPLICIT_STEP_LIMIT = 1.0
"""The largest eigenvalue of dt M⁻¹ J_Eᵀ D J_E the printed (explicit) Euler step may have: half its stability
bound, 2, for the poses the arm moves through (:func:`check_explicit_step`)."""


_new_tuple = tuple.__new__  # builds a named tuple from its fields in order, without a Python-level call


def _norm(v: Vec) -> float:
    """|v| of a 3-vector: math.hypot of its floats, a third of ``sqrt(v @ v)``'s call overhead."""
    return math.hypot(*v.tolist())


def explicit_step_ratio(M: Mat, J_E: Mat, D: Mat, dt: float) -> float:
    """The largest |eigenvalue| of dt M⁻¹ J_Eᵀ D J_E: the viscous wrench's (eq 40) damping of the joint velocity
    in one explicit Euler step. The step θ̇⁺ = (I - dt M⁻¹ J_Eᵀ D J_E) θ̇ + ... decays only while it is below 2;
    above, the velocity flips sign every tick and grows until the limits hold it (J_E's rotation rows equal
    J_G's; its translation, with k_f, is the smaller part)."""
    return float(np.max(np.abs(np.linalg.eigvals(dt * np.linalg.solve(M, J_E.T @ D @ J_E)))))


def check_explicit_step(cfg: Config, model: RobotModel, q: Vec) -> None:
    """ConfigError when ``motion.integrator: explicit`` cannot integrate the configured viscous damping at the
    control rate on this arm at joints ``q`` (:func:`explicit_step_ratio` over :data:`EXPLICIT_STEP_LIMIT`).

    Measured on the virtual model (a 5 N push and a 0.2 N m twist, 1.5 s): the joint accelerations flipped sign
    on 43-99 % of the ticks at ratios 2.3-4 (Panda k_t 20, FR3 k_t 0.6, UR5 k_t 40), on none at 1.3-1.7 (FR3
    k_t 0.3, UR5 k_t 30); the printed k_t = 150 N m s gives 30 on the Panda, 668 on the FR3 (its wrist is
    lighter). ``semi_implicit`` (the default) is stable for any damping."""
    if cfg.motion.integrator != "explicit":
        return
    v = cfg.viscous
    kin = model.kinematics(q, np.zeros(model.nv))
    for key, k_t in (("viscous.k_t", v.k_t), ("viscous.k_t_unguided", v.k_t_unguided)):
        ratio = explicit_step_ratio(kin.M, kin.J_E, np.diag([k_t] * 3 + [v.k_f] * 3), cfg.robot.dt)
        if ratio > EXPLICIT_STEP_LIMIT:
            raise ConfigError(
                f"'motion.integrator: explicit' cannot integrate '{key}' ({k_t:g} N m s) at "
                f"{cfg.robot.control_rate_hz:g} Hz on the {cfg.robot.kind}: dt M^-1 J^T D J reaches {ratio:.3g} "
                f"(at most {EXPLICIT_STEP_LIMIT:g}; above 2 the joints chatter at the limits). Use "
                f"'semi_implicit' (the default), or lower '{key}' to {k_t * EXPLICIT_STEP_LIMIT / ratio:.3g}",
                "motion.integrator",
            )


def check_explicit_step_at_home(cfg: Config) -> None:
    """:func:`check_explicit_step` on ``cfg``'s arm (its model built here) at its home pose: what the command
    line asks before a run starts, so the refusal is one line there rather than an error in the loop's process."""
    if cfg.motion.integrator == "explicit":
        model = RobotModel(cfg.robot.kind, ScopeGeometry.from_config(cfg.scope))
        check_explicit_step(cfg, model, np.array(arm_spec(cfg.robot.kind).home_pose, dtype=float))


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


class TickResult(NamedTuple):
    """What one tick produced (a named tuple: built every millisecond, it must be cheap)."""

    time: float
    q_ref: Vec
    dq_ref: Vec
    ddq_ref: Vec
    tau: Vec
    wrenches: dict[str, Vec]  # every running cue's wrench by its name: the paper's about their own points
    # (rcm p_R, interaction p_H, tracking p_C, viscous p_G), the plugins' about p_G
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
    events: tuple[InputEvent, ...] | list[InputEvent] = ()
    telemetry: dict[str, tuple[float, ...]] | None = None  # the Python cues' telemetry fields by cue name

    @property
    def rcm_error(self) -> float:
        e = self.e_R
        return math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])


class Controller:
    """The unified wrench controller (paper Sec. III) producing 1 kHz joint position references.

    The maths of the tick is compiled (:mod:`lapwrench.tick_core`); :meth:`reset` binds and warms it
    up, so the first tick runs at full speed.

    The cues are those of the configuration's ``cues:`` section (:func:`~lapwrench.wrenches.registry.build_cues`)
    plus ``extra_cues`` (objects built in code, e.g. by the UI or a test). The paper's run inside the
    compiled tick; the others (plugins) in Python between its two stages.
    """

    def __init__(
        self,
        cfg: Config,
        model: RobotModel | None = None,
        extra_cues: Sequence[Cue] = (),
    ) -> None:
        self.cfg = cfg
        self.model = model or RobotModel(cfg.robot.kind, ScopeGeometry.from_config(cfg.scope))
        self.dt = cfg.robot.dt
        self.cues: list[Cue] = build_cues(cfg) + list(extra_cues)
        names = [c.name for c in self.cues]
        if len(set(names)) != len(names):
            raise ValueError(f"cue names must be unique, got {sorted(n for n in set(names) if names.count(n) > 1)}")
        self.validator = InputValidator(
            cfg.interaction, cfg.camera, self.model.limits, cfg.inputs.max_image_age,
            max_instruments=cfg.inputs.max_instruments, inputs=input_specs(self.cues),
        )
        self.params = TickParams.from_config(cfg, self.model.limits)
        self.python_cues = [c for c in self.cues if not c.fused]
        self.shaper = ReferenceShaper(
            self.model.limits, self.dt, cfg.robot.limit_fraction, cfg.robot.position_margin
        )
        self.envelope = Envelope(cfg.envelope, cfg.scope.length, self.dt)
        self.feedback = MeasuredFeedback(self.model, cfg.scope.length, self.dt, 2.0 * cfg.safety.max_rcm_error)
        self.ref: ReferenceState | None = None
        self.rcm: AdaptiveRcm | None = None
        self.compiled: CompiledTick | None = None
        self.delta = 0.0  # this tick's grip gain δ (eq 7) and contact count
        self.contacts = 0
        self.stopping = False  # latched when the RCM task cannot be kept inside the joint limits
        self.infeasible_ticks = 0
        self.events: deque[InputEvent] = deque(maxlen=MAX_KEPT_EVENTS)
        self.event_counts: Counter[str] = Counter()
        # Test seam: f(reference, a_lo, a_hi) -> (a_lo, a_hi) narrows the joint box of a tick.
        self.bounds_hook: Callable[[ReferenceState, Vec, Vec], tuple[Vec, Vec]] | None = None
        self._max_rcm_error = cfg.inputs.max_rcm_error
        n = self.model.nv
        self._box_names = tuple(f"joint{i + 1}" for i in range(n))
        self._hard = np.arange(n + 4) < n  # the joint box is hard, the envelope gives way to it
        self._hard.flags.writeable = False
        self.warm_up()

    def warm_up(self) -> None:
        """Compile the tick (or load it from numba's cache) now, at the middle of the joint ranges,
        so that :meth:`reset` after a robot connects never waits for the compiler. Leaves the
        controller un-reset."""
        lim = self.model.limits
        q = 0.5 * (lim.position_lower + lim.position_upper)
        self.reset(q)
        # one tick through every path: every input valid, the saturation QP forced by a hook
        z = np.zeros(3)
        frame = SensorFrame(
            0.0, ForceTorqueReading(np.array([1.0, 0.0, 0.0]), z, 0.0), TactileReading(np.full(64, 50.0), 0.0),
            InstrumentObservation(np.array([[100.0, 100.0]]), 0.0), RobotReading(q, np.zeros(self.model.nv), z, 0.0),
        )
        hook, self.bounds_hook = self.bounds_hook, lambda ref, lo, hi: (lo, lo + 1e-3)  # a narrow box: a QP
        try:
            self.tick(frame)
        finally:
            self.bounds_hook = hook
        self.ref = self.rcm = self.compiled = None
        self.shaper.clamped_ticks = 0
        self.events.clear()
        self.event_counts.clear()

    # -- setup --------------------------------------------------------------------------------
    def reset(self, q0: Vec, p_R: Vec | None = None, tare_q: Vec | None = None) -> None:
        """Start at rest at ``q0``; the RCM point is eq (18) unless ``p_R`` is given; ``tare_q``: the joints
        at which the F/T was tared with the handle untouched (default ``q0``), from where the grip's
        weight is taken off (:mod:`lapwrench.wrenches.grip_weight`). Binds and warms up the compiled
        tick (seconds on a fresh install while numba compiles, milliseconds from its cache)."""
        q0 = np.asarray(q0, dtype=float)
        n = self.model.nq
        if q0.shape != (n,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"initial configuration must be {n} finite joint positions")
        lim = self.model.limits
        if np.any(q0 < lim.position_lower) or np.any(q0 > lim.position_upper):
            raise ValueError("initial configuration is outside the joint limits")
        check_explicit_step(self.cfg, self.model, q0)
        R_H_tare = None if tare_q is None else self._tare_rotation(tare_q)  # checked before anything changes
        rest = np.zeros(self.model.nv)
        self.ref = ReferenceState(q0.copy(), rest.copy(), rest.copy())
        kin = self.model.kinematics(q0, rest)
        if p_R is None:
            p_R = initial_rcm_point(kin, self.cfg.scope.length, self.cfg.scope.lambda0)
        self.rcm = AdaptiveRcm(self.cfg.adaptive_rcm, np.asarray(p_R, dtype=float))
        self.envelope.reset(kin)
        self.feedback.reset()
        # every runner tares the F/T with the handle untouched at the pose it first starts the controller
        # from; the grip's weight is taken off relative to {H} there (lapwrench.wrenches.grip_weight)
        tare = FtTare.at(kin.R_H if R_H_tare is None else R_H_tare)
        self.compiled = CompiledTick(self.params, self.rcm, self.feedback, self.python_cues, tare)
        terms = self.model.terms(q0, rest)
        assert self.envelope.R_E0 is not None
        self.compiled.bind(terms, self.envelope.R_E0)
        self.stopping = False
        self.infeasible_ticks = 0
        self.events.clear()
        self.event_counts.clear()

    def _tare_rotation(self, tare_q: Vec) -> Vec:
        """{H}'s rotation at the joints ``tare_q`` (checked like ``q0``)."""
        try:
            q = np.asarray(tare_q, dtype=float)
        except (TypeError, ValueError):
            q = np.zeros(0)
        if q.shape != (self.model.nq,) or not np.all(np.isfinite(q)):
            raise ValueError(f"tare_q must be {self.model.nq} finite joint positions")
        return self.model.kinematics(q, np.zeros(self.model.nv)).R_H.copy()

    # -- the tick -----------------------------------------------------------------------------
    def tick(self, frame: SensorFrame) -> TickResult:
        if self.ref is None or self.rcm is None or self.compiled is None:
            raise RuntimeError("call Controller.reset(q0) before tick()")
        # 1. sensors: validate at the edge; kinematics at the reference (the virtual model's state)
        inputs = self.validator.validate(frame)
        if inputs.events:
            self._report(inputs.events)
        ref = self.ref
        terms = self.model.terms(ref.q, ref.dq)
        assert self.envelope.R_E0 is not None

        # 2-7. adaptive RCM point, geometry, wrenches, allocation, integration, limit rows (compiled)
        r = self.compiled.run(frame.time, terms, inputs, ref.ddq, self.stopping, self.envelope.R_E0,
                              self.bounds_hook is None)
        self.delta, self.contacts = r.delta, r.contacts
        if r.non_finite:
            self._report([InputEvent(frame.time, "controller", "non-finite torque; braking")])
        if r.cue_faults:
            self._report([InputEvent(frame.time, "cues", msg) for msg in r.cue_faults])

        # 7. limits and envelope met by the lower-priority motion only (motion/saturation.py) → command
        if r.admitted:  # the desired acceleration met every limit: nothing to saturate (the common case)
            self.infeasible_ticks = 0
            limits_active: tuple[str, ...] = ()
            (q, dq, ddq), clamped = r.ref, r.clamped  # type: ignore[misc]
        else:
            sat = self._saturate(r, frame.time)
            limits_active = tuple(dict.fromkeys(sat.saturated + sat.dropped))
            if r.ref is None:
                q, dq, ddq, clamped = advance_reference(ref.q, ref.dq, sat.a, self._a_lo, self._a_hi, self.dt)
            else:
                (q, dq, ddq), clamped = r.ref, r.clamped
        self.shaper.clamped_ticks += bool(clamped)
        self.ref = _new_tuple(ReferenceState, (q, dq, ddq))  # without the keyword-handling constructor

        e_norm = _norm(r.e_R)
        if e_norm > self._max_rcm_error:
            self._report([InputEvent(frame.time, "rcm", f"RCM error {e_norm * 1e3:.1f} mm")])
        wrenches = r.wrenches
        p = self.params
        handle = p.cue_interaction and r.delta > 0.0 and inputs.ft is not None
        mode = self._mode(handle, p.cue_tracking and inputs.instruments is not None, inputs.instruments, wrenches)
        return TickResult._make((  # the fields in order: _make skips the keyword-handling constructor (1 µs)
            frame.time, q, dq, ddq, r.tau, wrenches, r.W_n, r.e_R, r.p_R, r.p_G, r.delta, r.contacts, mode,
            r.residual_lateral, r.residual, limits_active, self.stopping, inputs.events, r.telemetry or None,
        ))

    # -- pieces of the tick -------------------------------------------------------------------
    def _report(self, events: list[InputEvent]) -> None:
        """Keep the latest events (bounded) and count them all by source."""
        for e in events:
            self.events.append(e)
            self.event_counts[e.source] += 1

    @staticmethod
    def _mode(
        handle_engaged: bool, tracking_on: bool, instruments: InstrumentObservation | None, wrenches: dict[str, Vec]
    ) -> Mode:
        """:func:`classify_mode` of this tick; the force norms only when both cues are engaged (the
        only case that compares them)."""
        tracking_engaged = tracking_on and instruments is not None and len(instruments.points) > 0
        if handle_engaged and tracking_engaged:
            return classify_mode(True, True, _norm(wrenches["interaction"][3:]), _norm(wrenches["tracking"][3:]))
        return classify_mode(handle_engaged, tracking_engaged, 0.0, 0.0)

    def _saturate(self, r: StageResult, t: float) -> SaturationResult:
        """Joint limits and the envelope met by changing the lower-priority motion only (motion/saturation.py).

        The task is the RCM error's two lateral rates: J = [x_E  y_E]ᵀ J_R (e_R ⟂ d_z, so the third
        row carries nothing). If the task itself cannot stay inside the joint limits for
        ``INFEASIBLE_TICKS_TO_STOP`` ticks in a row (one such tick is clipped into the limits), the
        controller latches :attr:`stopping`: the cues are switched off and the null-space motion is
        braked with time constant ``motion.stop_time`` while the RCM task keeps acting, down to rest
        (the brake is part of the compiled motion stage).
        Called only when the desired acceleration breaks a limit (``tick`` handles the admitted case).
        """
        assert self.compiled is not None and self.ref is not None
        s = self.compiled.sat
        names = self._box_names + tuple(WALL_NAMES[i] for i in s.wall)
        if r.ref is not None:  # saturated by the compiled step with every row hard: the common case
            at = r.at_bound
            sat = SaturationResult(r.ref[2], tuple(names[i] for i in range(len(names)) if at >> i & 1), (), True)
        else:
            n = s.a_d.shape[0]
            m = n + 4 if self.params.envelope_enabled else n
            lo, hi = s.lo[:m].copy(), s.hi[:m].copy()
            if self.bounds_hook is not None:
                lo[:n], hi[:n] = self.bounds_hook(self.ref, lo[:n].copy(), hi[:n].copy())
            self._a_lo, self._a_hi = lo[:n], hi[:n]
            rows = LimitRows(s.C[:m].copy(), lo, hi, s.scale[:m].copy(), names[:m], self._hard[:m])
            sat = saturate(s.a_d.copy(), s.J_task.copy(), s.M.copy(), rows)
        self.infeasible_ticks = 0 if sat.feasible else self.infeasible_ticks + 1
        if self.infeasible_ticks >= INFEASIBLE_TICKS_TO_STOP and not self.stopping:
            self.stopping = True
            self._report([InputEvent(t, "controller", "RCM task cannot be kept inside the joint limits; stopping")])
        return sat

