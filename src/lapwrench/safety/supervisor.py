"""The safety supervisor: the last gate between the controller and the robot.

Every joint position command passes through :meth:`SafetySupervisor.filter` before it is written.
The supervisor is deliberately independent of the controller's
:class:`~lapwrench.motion.reference_shaper.ReferenceShaper`: it re-derives velocity, acceleration
and jerk from the history of the commands *it actually sent*, exactly as libfranka does
(backward differences at the control period: ``v = Δq/dt``, ``a = Δv/dt``, ``j = Δa/dt``, from
rest at the start pose), and checks them against the Franka limits. Then:

* **Command validation.** A command that is not one finite number per joint, leaves the joint position
  limits, breaks a velocity/acceleration/jerk limit, or is one from which the stop below could not end
  inside the position and velocity limits (:func:`~lapwrench.safety.checks.stop_reach`: full speed just
  short of a limit, full acceleration at full speed) is *replaced* by the next sample of a
  jerk-limited stop, an event is logged and the supervisor latches into a stop with an alarm.
  A controller that produced one bad command is not trusted for the next. Every command accepted
  is thus one the stop can bring to rest inside the limits, whenever a fault comes.
* **Measured-state watches** (issue 9), joint limits and deadlines: see
  :mod:`lapwrench.safety.watches`. The caller measures the scope (:func:`measure_scope` at the
  robot's measured joints); build the thresholds from the YAML configuration with
  :meth:`SupervisorConfig.from_config`. A controller's *reference* state never feeds these
  watches, nor does a simulator's ground truth.
* **Clean stop.** :meth:`stop` brings the reference to rest: each joint's acceleration is ramped
  at most ``jerk·dt`` per cycle towards ``-sign(v)·min(a_max, a_ramp(v))``, ``a_ramp`` the largest
  deceleration from which the acceleration can still be ramped back to zero in jerk steps exactly
  when the velocity reaches zero (the discrete form of ``sqrt(2 j |v|)``), so velocity,
  acceleration and jerk all stay inside the (scaled) limits and the stream ends at rest (constant
  position). :attr:`at_rest` tells when the caller may
  disconnect.
* **Resume.** A later :meth:`start` (a restart after a hold, the robot still holding the last command)
  keeps the command history: the robot saw the held reference, not the measured pose the controller
  restarts from, and the two differ by the tracking error. That offset is added to the controller's
  commands and phased out smoothly (:data:`RESUME_FRACTION` of the limits), so the reference the robot
  receives does not jump at a resume.

Events are structured :class:`SupervisorEvent` (time, kind, message) and kept in
:attr:`SafetySupervisor.events` (bounded) and :attr:`SafetySupervisor.pending` (drained by the
logger each cycle).

The thresholds, states and events live in :mod:`lapwrench.safety.config`, the compiled checks and
:func:`measure_scope` in :mod:`lapwrench.safety.checks`; every one of those names is importable
from here.
"""

from __future__ import annotations

import math

import numpy as np

from lapwrench.inputs import is_f64_c, real_array
from lapwrench.jit import bind
from lapwrench.robot.limits import JointLimits
from lapwrench.safety.checks import (
    MeasuredScope,
    accept_command,
    command_violation,
    measure_scope,
    measured_joints_room,
    measured_step,
    nearest_limit,
    stop_reach,
)
from lapwrench.safety.config import SupervisorConfig, SupervisorEvent, SupervisorState
from lapwrench.safety.watches import CONTROLLER_STOP_TIMEOUT, SupervisorWatches
from lapwrench.spatial import Vec

# A resume phases out the held reference's offset from the start pose using this fraction of the
# velocity/acceleration/jerk limits (the controller's commands use up to robot.limit_fraction, 0.9,
# of them, and the check allows 1.0) ...
RESUME_FRACTION = 0.05
# ... for an offset up to this (rad, any joint); a larger one is no tracking error: the robot was moved
# (or reconnected after a recovery) and the supervisor starts afresh at the start pose, with an event.
RESUME_MAX_OFFSET = 0.02

__all__ = [
    "CONTROLLER_STOP_TIMEOUT",
    "RESUME_FRACTION",
    "RESUME_MAX_OFFSET",
    "MeasuredScope",
    "SafetySupervisor",
    "SupervisorConfig",
    "SupervisorEvent",
    "SupervisorState",
    "command_violation",
    "measure_scope",
    "nearest_limit",
    "stop_reach",
]


class SafetySupervisor(SupervisorWatches):
    """Validates, and if needed replaces, every command; watches measured state and deadlines
    (:class:`~lapwrench.safety.watches.SupervisorWatches`).

    Args:
        limits: The robot's joint limits (:attr:`lapwrench.robot.model.RobotModel.limits`).
        dt: Control period (s).
        config: Thresholds (:class:`SupervisorConfig`).
    """

    def __init__(self, limits: JointLimits, dt: float, config: SupervisorConfig | None = None) -> None:
        super().__init__(config or SupervisorConfig(), limits.position_lower, limits.position_upper)
        self.dt = float(dt)
        self.limits = limits
        c = self.cfg
        self._v_max = np.ascontiguousarray(limits.velocity * c.check_fraction, dtype=float)
        self._a_max = np.ascontiguousarray(limits.acceleration * c.check_fraction, dtype=float)
        self._j_max = np.ascontiguousarray(limits.jerk * c.check_fraction, dtype=float)
        stop = limits.scaled(c.stop_fraction)
        self._stop_a = np.ascontiguousarray(stop.acceleration, dtype=float)
        self._stop_j = np.ascontiguousarray(stop.jerk, dtype=float)
        self.replaced_commands = 0
        self.n_joints = int(limits.position_lower.shape[0])
        # The command history as libfranka differentiates it: rows q, v, a of the last command sent,
        # updated in place (``_q``, ``_v``, ``_a`` are views of its rows).
        self._history = np.zeros((3, self.n_joints))
        self._q, self._v, self._a = self._history
        self._started = False
        self._resume_offset = np.zeros(self.n_joints)  # held reference - start pose, phased out (start)
        self._resume_cycles = 0  # cycles the phase-out takes ...
        self._resume_left = 0  # ... and those still to come
        # The compiled checks bound to their argument types now (:func:`lapwrench.jit.bind`: no dispatch
        # per call, nothing compiles in the first cycle); every call passes C-contiguous float64 vectors.
        z = np.zeros(self.n_joints)
        limits_args = (
            self._lo, self._hi, 0.0, self._v_max, self._a_max, self._j_max, self._stop_a, self._stop_j, self.dt
        )
        self._command_violation = bind(command_violation, z, z, z, z, *limits_args)
        self._accept_command = bind(accept_command, z, np.zeros((3, self.n_joints)), *limits_args)
        self._nearest_limit = bind(nearest_limit, z, self._lo, self._hi)
        self._joints_room = bind(measured_joints_room, z, self._lo, self._hi)
        self._measured_step = bind(measured_step, z, z)

    # -- state --------------------------------------------------------------------------------
    def start(self, q0: Vec, time: float = 0.0) -> None:
        """Start supervising from rest at ``q0`` (the robot's measured joints).

        A restart after a hold, within :data:`RESUME_MAX_OFFSET` of the held reference, resumes from that
        reference instead (module docstring): the controller's commands, which begin at ``q0``, reach
        the robot shifted by the offset, phased out in :attr:`resume_cycles` cycles.
        """
        q0 = np.asarray(q0, dtype=float)
        n = self.n_joints
        if q0.shape != (n,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"supervisor start pose must be {n} finite joint positions")
        offset = self._q - q0
        far = float(np.max(np.abs(offset)))
        resume = self._started and self.state is SupervisorState.HOLDING and far <= RESUME_MAX_OFFSET
        self._resume_cycles = self._resume_left = self._phase_out_cycles(offset) if resume else 0
        if resume:
            self._resume_offset[:] = offset  # the history stays: what the robot saw last
            message = (f"supervision resumed from the held reference, {far * 1e3:.3f} mrad from the start pose,"
                       f" phased out over {self._resume_cycles} cycles")
        else:
            if self._started and self.state is SupervisorState.HOLDING:
                self.event(time, "start_afresh", f"the start pose is {far:.4f} rad from the held reference")
            self._history[0] = q0
            self._history[1:] = 0.0
            message = "supervision started at rest"
        self.state = SupervisorState.RUNNING
        self.alarm, self.alarm_reason = False, None
        self.consecutive_misses = 0
        self._residual_over_since = None
        self._controller_stop_since = None
        self._q_measured_seen = False  # the jump watch starts with the next reading
        self._started = True
        self.event(time, "start", message)

    def continue_from(self, other: SafetySupervisor) -> None:
        """Take over ``other``'s command stream: a supervisor with new thresholds (a parameter change)
        for the same robot, whose next :meth:`start` resumes from the reference ``other`` holds, as a
        restart after a hold does (module docstring). A fresh supervisor would start its history at the
        measured pose while the robot holds ``other``'s last command, a step of the tracking error
        (0.9 mrad, 9x the jerk limit measured through the UI's parameter change).

        Raises:
            ValueError: ``other`` is not at rest (:attr:`at_rest`: stop it first) or watches other joints
                or other limits.
        """
        if not (other._started and other.at_rest):
            raise ValueError("the supervisor handed over must be at rest: stop it first")
        same = other.n_joints == self.n_joints and all(
            np.array_equal(a, b) for a, b in ((other._lo, self._lo), (other._hi, self._hi),
                                              (other.limits.velocity, self.limits.velocity),
                                              (other.limits.acceleration, self.limits.acceleration),
                                              (other.limits.jerk, self.limits.jerk)))
        if not same or other.dt != self.dt:
            raise ValueError("the supervisor handed over watches another robot (joints, limits or period differ)")
        self._history[:] = other._history
        self._started, self.state = True, SupervisorState.HOLDING

    def _phase_out_cycles(self, offset: Vec) -> int:
        """Cycles of a minimum-jerk phase-out of ``offset`` using :data:`RESUME_FRACTION` of the limits
        (a quintic over T: peak speed 1.875 d/T, acceleration 5.774 d/T², jerk 60 d/T³)."""
        d = np.abs(offset)
        if not d.any():
            return 0
        f = RESUME_FRACTION
        t = np.maximum.reduce([1.875 * d / (f * self._v_max), np.sqrt(5.774 * d / (f * self._a_max)),
                               np.cbrt(60.0 * d / (f * self._j_max))])
        return max(1, math.ceil(float(np.max(t)) / self.dt))

    @property
    def resume_cycles(self) -> int:
        """Cycles over which the last :meth:`start` phases out the held reference's offset (0: none)."""
        return self._resume_cycles

    def _resumed(self, q_cmd: object) -> object:
        """``q_cmd`` plus this cycle's share of the resume offset (quintic, from all of it to none)."""
        q = real_array(q_cmd)
        if q is None or q.shape != self._resume_offset.shape:
            return q_cmd  # refused by the check as it is
        self._resume_left -= 1
        tau = 1.0 - self._resume_left / self._resume_cycles
        w = 1.0 - tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        return q + w * self._resume_offset

    @property
    def command_state(self) -> tuple[Vec, Vec, Vec]:
        """(q, v, a) of the last command sent, as libfranka differentiates them (copies)."""
        return self._q.copy(), self._v.copy(), self._a.copy()

    @property
    def at_rest(self) -> bool:
        """True once a stop has completed (the reference is constant)."""
        return self.state is SupervisorState.HOLDING

    # -- checks -------------------------------------------------------------------------------
    def check_command(self, q_cmd: object) -> tuple[str, str] | None:
        """(kind, message) if ``q_cmd`` is not a valid next command after the history, else None."""
        q = real_array(q_cmd)  # None for text, objects or complex values
        if q is None:
            return "command_invalid", "command is not numeric"
        if q.shape != self._q.shape:
            return "command_invalid", f"command has shape {q.shape}, expected {self._q.shape}"
        if not math.isfinite(q.sum()):
            return "command_nonfinite", f"non-finite command {np.array2string(q, precision=3)}"
        code, j, value = self._command_violation(
            q, self._q, self._v, self._a, self._lo, self._hi, float(self.cfg.position_tolerance), self._v_max,
            self._a_max, self._j_max, self._stop_a, self._stop_j, self.dt,
        )
        return None if code == 0 else self._violation(q, code, j, value)

    def _violation(self, q: np.ndarray, code: int, j: int, value: float) -> tuple[str, str]:
        """(kind, message) of a violation code of :func:`accept_command` for the command ``q``."""
        if code == 5:
            return "command_nonfinite", f"non-finite command {np.array2string(q, precision=3)}"
        if code == 1:
            return "command_position", (
                f"joint {j + 1} command {q[j]:.4f} rad outside [{self._lo[j]:.4f}, {self._hi[j]:.4f}]"
            )
        if code == 6:
            return "command_stop_position", (
                f"joint {j + 1} command {q[j]:.4f} rad at {(q[j] - self._q[j]) / self.dt:.4g} rad/s: a stop from it"
                f" could reach {value:.4f} rad, outside [{self._lo[j]:.4f}, {self._hi[j]:.4f}]"
            )
        if code == 7:
            return "command_stop_velocity", (
                f"joint {j + 1} command: a stop from it could reach {value:.4g} rad/s (its acceleration ramped out),"
                f" over {self._v_max[j]:.4g}"
            )
        kind, limit, unit = (
            ("command_velocity", self._v_max, "rad/s"),
            ("command_acceleration", self._a_max, "rad/s^2"),
            ("command_jerk", self._j_max, "rad/s^3"),
        )[code - 2]
        return kind, f"joint {j + 1} {kind.split('_')[1]} {value:.4g} {unit} exceeds {limit[j]:.4g}"

    def _accept(self, q: Vec) -> None:
        dt = self.dt
        v = (q - self._q) / dt
        self._a[:] = (v - self._v) / dt
        self._v[:] = v
        self._q[:] = q

    def _stop_step(self) -> Vec:
        """Next sample of the jerk-limited stop from the current command state."""
        dt = self.dt
        v, a = self._v, self._a
        jdt = self._stop_j * dt
        # largest deceleration a after which ramping a back down in jerk steps (a - jdt, ..., 0)
        # removes exactly the velocity left: |v| = dt a (a + jdt) / (2 jdt)
        a_ramp = 0.5 * (np.sqrt(jdt * jdt + 8.0 * jdt * np.abs(v) / dt) - jdt)
        target = -np.sign(v) * np.minimum(self._stop_a, a_ramp)
        a_new = np.clip(target, a - jdt, a + jdt)
        v_new = v + a_new * dt
        # if this step would reverse the velocity, aim at zero instead (still within one jerk
        # step of the previous acceleration; a remaining sliver is braked on the next cycles)
        crossing = np.sign(v_new) * np.sign(v) < 0
        if crossing.any():
            a_new = np.where(crossing, np.clip(-v / dt, a - jdt, a + jdt), a_new)
            v_new = v + a_new * dt
        q_new = self._q + v_new * dt
        self._a[:], self._v[:], self._q[:] = a_new, v_new, q_new
        if (
            np.max(np.abs(v_new)) < self.cfg.rest_velocity
            and np.max(np.abs(a_new)) <= np.min(jdt)
        ):
            # from here the position is held: libfranka then sees v -> 0 (a change of at most
            # rest_velocity/dt in acceleration) and a -> 0 on the next cycle
            self.state = SupervisorState.HOLDING
        return self._q.copy()

    # -- the gate -----------------------------------------------------------------------------
    def filter(
        self,
        time: float,
        q_cmd: object,
        *,
        rcm_error: float | None = None,
        depth: float | None = None,
        residual: Vec | None = None,
        q_measured: Vec | None = None,
        compute_time: float | None = None,
        controller_stopping: bool = False,
    ) -> Vec:
        """The command to send this cycle.

        Every watched value is a *measured* one (:func:`measure_scope`); ``None`` skips its watch.

        Args:
            time: Session time (s), for events.
            q_cmd: The controller's joint position reference (ignored while stopping or holding).
            rcm_error: RCM error (m) at the measured joints, over ``max_rcm_error`` → hold.
            depth: Insertion depth (m) at the measured joints, outside ``[depth_min, depth_max]`` → hold.
            residual: ΔF (eq 19, N, 3-vector): handle F/T minus the robot's external force estimate;
                |ΔF| over ``max_residual_force`` → hold. None when either sensor is unavailable.
            q_measured: The robot's measured joints (rad): near a limit or not finite → hold.
            compute_time: This cycle's busy time (s; :class:`~lapwrench.loop.ControlLoop`: its compute time plus
                the loop's own work after the previous command); None skips the deadline watch.
            controller_stopping: The controller could not keep the RCM task inside the joint limits
                and is braking its reference to rest while keeping the task as far as it can
                (``TickResult.rcm_infeasible``): its commands pass until they are at rest (or for
                ``CONTROLLER_STOP_TIMEOUT``), then the arm holds with an alarm.
        """
        if not self._started:
            raise RuntimeError("call SafetySupervisor.start(q0) before filter()")
        if compute_time is not None:
            self._watch_deadline(time, compute_time)
        if q_measured is not None:
            self._watch_joints(time, q_measured)
        else:
            self._q_measured_seen = False  # a later reading is not compared with one from before the gap
        self._watch_scope(time, rcm_error, depth, residual)
        self._watch_controller_stop(time, controller_stopping)

        if self.state is SupervisorState.HOLDING:
            q = self._q.copy()
            self._accept(q)
            return q
        if self.state is SupervisorState.STOPPING:
            return self._stop_step()
        if self._resume_left:
            q_cmd = self._resumed(q_cmd)
        problem: tuple[str, str] | None
        if is_f64_c(q_cmd) and q_cmd.shape == self._q.shape:  # the usual command: one compiled check
            code, j, value = self._accept_command(
                q_cmd, self._history, self._lo, self._hi, float(self.cfg.position_tolerance), self._v_max,
                self._a_max, self._j_max, self._stop_a, self._stop_j, self.dt,
            )
            if code == 0:
                return q_cmd.copy()
            problem = self._violation(q_cmd, code, j, value)
        else:
            problem = self.check_command(q_cmd)
            if problem is None:
                q = np.asarray(q_cmd, dtype=float)
                self._accept(q)
                return q.copy()
        kind, message = problem
        self.replaced_commands += 1
        self.raise_alarm(time, kind, f"{message}; replaced by a stop")
        return self._stop_step()
