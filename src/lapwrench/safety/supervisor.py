"""The safety supervisor: the last gate between the controller and the robot.

Every joint position command passes through :meth:`SafetySupervisor.filter` before it is written.
The supervisor is deliberately independent of the controller's
:class:`~lapwrench.motion.reference_shaper.ReferenceShaper`: it re-derives velocity, acceleration
and jerk from the history of the commands *it actually sent*, exactly as libfranka does
(backward differences at the control period: ``v = Δq/dt``, ``a = Δv/dt``, ``j = Δa/dt``, from
rest at the start pose), and checks them against the Franka limits. Then:

* **Command validation.** A command that is not 7 finite numbers, leaves the joint position
  limits, or breaks a velocity/acceleration/jerk limit is *replaced* by the next sample of a
  jerk-limited stop, an event is logged and the supervisor latches into a stop with an alarm.
  A controller that produced one bad command is not trusted for the next.
* **Measured-state watches** (issue 9), the same in the simulation and on the robot; each one
  holds the arm (the same smooth, jerk-limited stop) with an alarm naming the quantity and its
  value. The caller measures them (:func:`measure_scope` at the robot's measured joints):

  - ``rcm_error``: the RCM error from the *measured* joints, the distance (m) from the
    controller's RCM point p_R to the scope axis, over ``max_rcm_error`` (default 5 mm);
  - ``insertion_depth``: the measured depth (m) of the scope tip beyond p_R, outside
    ``[depth_min, depth_max]`` (the envelope's depth range widened by ``safety.depth_tolerance``);
  - ``residual_force``: the residual |ΔF| (eq 19, N; the handle F/T minus the robot's external
    force estimate: the scope's force on the incision wall) over ``max_residual_force``;
  - ``joints_nonfinite``: measured joints that are not finite numbers.

  A non-finite measured value holds too. Build the thresholds from the YAML configuration with
  :meth:`SupervisorConfig.from_config`. A controller's *reference* state never feeds these
  watches, nor does a simulator's ground truth.
* **Joint limits.** A *measured* joint closer than ``joint_warn_margin`` to a limit logs an event;
  closer than ``joint_stop_margin`` → stop and alarm (the shaper keeps the reference
  ``position_margin`` inside, so this means the robot is not following).
* **Deadlines.** A cycle whose compute time exceeds ``cycle_budget`` is a deadline miss (counted,
  logged with rate limiting); ``max_consecutive_misses`` in a row → stop and alarm.
* **Clean stop.** :meth:`stop` brings the reference to rest: each joint's acceleration is ramped
  at most ``jerk·dt`` per cycle towards ``-sign(v)·min(a_max, a_ramp(v))``, ``a_ramp`` the largest
  deceleration from which the acceleration can still be ramped back to zero in jerk steps exactly
  when the velocity reaches zero (the discrete form of ``sqrt(2 j |v|)``), so velocity,
  acceleration and jerk all stay inside the (scaled) limits and the stream ends at rest (constant
  position). :attr:`at_rest` tells when the caller may
  disconnect.

Events are structured :class:`SupervisorEvent` (time, kind, message) and kept in
:attr:`SafetySupervisor.events` (bounded) and :attr:`SafetySupervisor.pending` (drained by the
logger each cycle).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from lapwrench.config import Config, EnvelopeConfig, SafetyConfig
from lapwrench.jit import kernel
from lapwrench.rcm.geometry import axis_rcm_error_and_depth
from lapwrench.robot.limits import JointLimits
from lapwrench.robot.model import RobotModel
from lapwrench.spatial import Vec

# Seconds a braking controller (TickResult.rcm_infeasible) may take to reach rest before the hold.
CONTROLLER_STOP_TIMEOUT = 1.0


def _measured_bounds(safety: SafetyConfig, envelope: EnvelopeConfig) -> dict[str, float]:
    """The supervisor's measured-state bounds from the config sections (m, m, m, N)."""
    return {
        "max_rcm_error": safety.max_rcm_error,
        "depth_min": envelope.depth_min - safety.depth_tolerance,
        "depth_max": envelope.depth_max + safety.depth_tolerance,
        "max_residual_force": safety.max_residual_force,
        "residual_force_time": safety.residual_force_time,
    }


_DEFAULT_BOUNDS = _measured_bounds(SafetyConfig(), EnvelopeConfig())  # those of data/default.yaml


class SupervisorState(StrEnum):
    """``running``: commands pass; ``stopping``: braking to rest; ``holding``: at rest, holding."""

    RUNNING = "running"
    STOPPING = "stopping"
    HOLDING = "holding"


@dataclass(frozen=True)
class SupervisorEvent:
    """One supervisor event. ``time`` is the loop's session time (s)."""

    time: float
    kind: str
    message: str


@dataclass(frozen=True)
class SupervisorConfig:
    """Supervisor thresholds.

    The measured-state bounds default to the shipped ``safety`` and ``envelope`` sections; build a
    loop's configuration with :meth:`from_config` so every loop reads them from the YAML the same way.

    Attributes:
        check_fraction: Fraction of the Franka velocity/acceleration/jerk limits a command may use
            (1.0: the hard limits; the controller's shaper uses ``robot.limit_fraction`` < 1).
        stop_fraction: Fraction of the limits used by the stop trajectory.
        position_tolerance: Slack (rad) on the position-limit check of commands.
        max_rcm_error: Measured RCM error (m) above which the robot holds with an alarm.
        depth_min: Measured insertion depth (m) below which the robot holds with an alarm.
        depth_max: Measured insertion depth (m) above which the robot holds with an alarm.
        max_residual_force: Residual |ΔF| (N, eq 19) above which the robot holds with an alarm ...
        residual_force_time: ... once it has stayed above for this long (s): the robot's force
            estimate lags the handle sensor, so a hand letting go of 30 N at once shows |ΔF| of
            ~26 N for about 25 ms without any load on the wall. A non-finite |ΔF| holds at once.
        joint_warn_margin: Measured distance (rad) to a joint limit that logs an event.
        joint_stop_margin: Measured distance (rad) to a joint limit that stops with an alarm.
        cycle_budget: Compute time (s) allowed per cycle; more is a deadline miss.
        max_consecutive_misses: Deadline misses in a row that stop with an alarm (0: never).
        rest_velocity: Velocity (rad/s) under which, with the acceleration ramped out, a stopping
            reference counts as at rest.
        max_events: Events kept in memory.
    """

    check_fraction: float = 1.0
    stop_fraction: float = 0.9
    position_tolerance: float = 1e-6
    max_rcm_error: float = _DEFAULT_BOUNDS["max_rcm_error"]
    depth_min: float = _DEFAULT_BOUNDS["depth_min"]
    depth_max: float = _DEFAULT_BOUNDS["depth_max"]
    max_residual_force: float = _DEFAULT_BOUNDS["max_residual_force"]
    residual_force_time: float = _DEFAULT_BOUNDS["residual_force_time"]
    joint_warn_margin: float = 0.04
    joint_stop_margin: float = 0.01
    cycle_budget: float = 0.0008
    max_consecutive_misses: int = 20
    rest_velocity: float = 1e-4
    max_events: int = 10_000

    def __post_init__(self) -> None:
        for name in (
            "check_fraction", "stop_fraction", "max_rcm_error", "max_residual_force", "cycle_budget", "rest_velocity"
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"supervisor.{name} must be positive, got {v!r}")
        if self.check_fraction > 1.0 or self.stop_fraction > 1.0:
            raise ValueError("supervisor check_fraction and stop_fraction must be <= 1")
        if not (math.isfinite(self.depth_min) and math.isfinite(self.depth_max) and self.depth_min < self.depth_max):
            raise ValueError(f"need finite depth_min < depth_max, got {self.depth_min!r}, {self.depth_max!r}")
        if not 0 <= self.joint_stop_margin <= self.joint_warn_margin:
            raise ValueError("need 0 <= joint_stop_margin <= joint_warn_margin")
        if self.max_consecutive_misses < 0:
            raise ValueError("max_consecutive_misses must be >= 0")

    @classmethod
    def from_config(cls, cfg: Config, **overrides: Any) -> SupervisorConfig:
        """The measured-state bounds of ``cfg.safety`` and ``cfg.envelope``; ``overrides`` set the
        other thresholds (or replace a bound)."""
        return cls(**{**_measured_bounds(cfg.safety, cfg.envelope), **overrides})


@dataclass(frozen=True)
class MeasuredScope:
    """The scope against the RCM point at the measured joints: ``rcm_error`` (m, distance from p_R
    to the scope axis, eq 27) and ``depth`` (m of scope tip beyond p_R along the shaft)."""

    rcm_error: float
    depth: float


def measure_scope(model: RobotModel, q_measured: Vec, p_R: Vec) -> MeasuredScope:
    """RCM error and insertion depth at the robot's *measured* joints, for the controller's p_R.

    One forward kinematics pass (:meth:`RobotModel.scope_axis_at`) and the formulas of
    :mod:`lapwrench.rcm.geometry`, about 10 µs. Non-finite joints or p_R propagate to NaN values
    and arrays of the wrong shape give NaN (the supervisor then holds).
    """
    q = np.asarray(q_measured, dtype=float)
    p = np.asarray(p_R, dtype=float)
    if q.shape != (7,) or p.shape != (3,):
        return MeasuredScope(math.nan, math.nan)
    axis = model.scope_axis_at(q)
    e, depth = axis_rcm_error_and_depth(axis.p_E, axis.d_z, axis.P, np.ascontiguousarray(p), float(model.length))
    return MeasuredScope(float(e), float(depth))


@kernel
def command_violation(
    q: Vec, q_prev: Vec, v_prev: Vec, a_prev: Vec, lo: Vec, hi: Vec, tol: float, v_max: Vec, a_max: Vec,
    j_max: Vec, dt: float,
) -> tuple[int, int, float]:
    """The first limit the command ``q`` breaks after the history (q, v, a) as libfranka differentiates
    it: (0 none | 1 position | 2 velocity | 3 acceleration | 4 jerk, joint, value)."""
    n = q.shape[0]
    for j in range(n):
        if q[j] < lo[j] - tol or q[j] > hi[j] + tol:
            return 1, j, q[j]
    v = (q - q_prev) / dt
    a = (v - v_prev) / dt
    jk = (a - a_prev) / dt
    for code, value, limit in ((2, v, v_max), (3, a, a_max), (4, jk, j_max)):
        worst, jw = 0.0, 0
        for j in range(n):
            r = abs(value[j]) / limit[j]
            if r > worst:
                worst, jw = r, j
        if worst > 1.0 + 1e-9:
            return code, jw, value[jw]
    return 0, 0, 0.0


@kernel
def nearest_limit(q: Vec, lo: Vec, hi: Vec) -> tuple[int, float]:
    """The joint nearest to one of its limits and its room (rad)."""
    jm, room = 0, np.inf
    for j in range(q.shape[0]):
        r = min(q[j] - lo[j], hi[j] - q[j])
        if r < room:
            jm, room = j, r
    return jm, room


def _rate_limited(count: int) -> bool:
    """Log the first 10 occurrences, then every 1000th."""
    return count <= 10 or count % 1000 == 0


class SafetySupervisor:
    """Validates, and if needed replaces, every command; watches measured state and deadlines.

    Args:
        limits: The robot's joint limits (:attr:`lapwrench.robot.model.RobotModel.limits`).
        dt: Control period (s).
        config: Thresholds (:class:`SupervisorConfig`).
    """

    def __init__(self, limits: JointLimits, dt: float, config: SupervisorConfig | None = None) -> None:
        self.cfg = config or SupervisorConfig()
        self.dt = float(dt)
        self.limits = limits
        c = self.cfg
        self._v_max = limits.velocity * c.check_fraction
        self._a_max = limits.acceleration * c.check_fraction
        self._j_max = limits.jerk * c.check_fraction
        stop = limits.scaled(c.stop_fraction)
        self._stop_a = stop.acceleration
        self._stop_j = stop.jerk
        self._lo = limits.position_lower
        self._hi = limits.position_upper
        self.events: deque[SupervisorEvent] = deque(maxlen=c.max_events)
        self.pending: list[SupervisorEvent] = []
        self.state = SupervisorState.HOLDING
        self.alarm = False
        self.alarm_reason: str | None = None
        self.deadline_misses = 0
        self.consecutive_misses = 0
        self.replaced_commands = 0
        self._counts: dict[str, int] = {}
        self._joint_warned = False
        self._residual_over_since: float | None = None
        self._controller_stop_since: float | None = None
        self._q = np.zeros(7)
        self._v = np.zeros(7)
        self._a = np.zeros(7)
        self._started = False
        # load the compiled checks now, not in the first cycle
        z = np.zeros(7)
        command_violation(z, z, z, z, self._lo, self._hi, 0.0, self._v_max, self._a_max, self._j_max, self.dt)
        nearest_limit(z, self._lo, self._hi)

    # -- state --------------------------------------------------------------------------------
    def start(self, q0: Vec, time: float = 0.0) -> None:
        """Start supervising from rest at ``q0`` (the robot's measured joints)."""
        q0 = np.asarray(q0, dtype=float)
        if q0.shape != (7,) or not np.all(np.isfinite(q0)):
            raise ValueError("supervisor start pose must be 7 finite joint positions")
        self._q, self._v, self._a = q0.copy(), np.zeros(7), np.zeros(7)
        self.state = SupervisorState.RUNNING
        self.alarm, self.alarm_reason = False, None
        self.consecutive_misses = 0
        self._residual_over_since = None
        self._controller_stop_since = None
        self._started = True
        self.event(time, "start", "supervision started at rest")

    @property
    def command_state(self) -> tuple[Vec, Vec, Vec]:
        """(q, v, a) of the last command sent, as libfranka differentiates them (copies)."""
        return self._q.copy(), self._v.copy(), self._a.copy()

    @property
    def at_rest(self) -> bool:
        """True once a stop has completed (the reference is constant)."""
        return self.state is SupervisorState.HOLDING

    def event(self, time: float, kind: str, message: str) -> SupervisorEvent:
        """Record an event."""
        ev = SupervisorEvent(float(time), kind, message)
        self.events.append(ev)
        self.pending.append(ev)
        return ev

    def counted_event(self, time: float, kind: str, message: str) -> None:
        """Record a repeated event, rate-limited (first 10, then every 1000th), counting all."""
        n = self._counts.get(kind, 0) + 1
        self._counts[kind] = n
        if _rate_limited(n):
            self.event(time, kind, f"{message} (occurrence {n})")

    def drain_events(self) -> list[SupervisorEvent]:
        """Events since the last call (for the logger)."""
        out, self.pending = self.pending, []
        return out

    def raise_alarm(self, time: float, kind: str, message: str) -> None:
        """Stop with an alarm (idempotent for the alarm reason: the first one is kept)."""
        if not self.alarm:
            self.alarm, self.alarm_reason = True, f"{kind}: {message}"
        self.event(time, kind, message)
        if self.state is SupervisorState.RUNNING:
            self.state = SupervisorState.STOPPING
            self.event(time, "stop", f"stopping ({kind})")

    def stop(self, time: float, reason: str = "stop requested") -> None:
        """Begin a clean stop to rest (no alarm). Keep calling :meth:`filter` until :attr:`at_rest`."""
        if self.state is SupervisorState.RUNNING:
            self.state = SupervisorState.STOPPING
            self.event(time, "stop", reason)

    # -- checks -------------------------------------------------------------------------------
    def check_command(self, q_cmd: object) -> tuple[str, str] | None:
        """(kind, message) if ``q_cmd`` is not a valid next command after the history, else None."""
        try:
            q = np.asarray(q_cmd, dtype=float)
        except (TypeError, ValueError):
            return "command_invalid", "command is not numeric"
        if q.shape != (7,):
            return "command_invalid", f"command has shape {q.shape}, expected (7,)"
        q = np.ascontiguousarray(q)
        if not math.isfinite(q.sum()):
            return "command_nonfinite", f"non-finite command {np.array2string(q, precision=3)}"
        code, j, value = command_violation(
            q, self._q, self._v, self._a, self._lo, self._hi, self.cfg.position_tolerance, self._v_max,
            self._a_max, self._j_max, self.dt,
        )
        if code == 0:
            return None
        if code == 1:
            return "command_position", (
                f"joint {j + 1} command {q[j]:.4f} rad outside [{self._lo[j]:.4f}, {self._hi[j]:.4f}]"
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
        self._a = (v - self._v) / dt
        self._v = v
        self._q = q.copy()

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
        self._a, self._v, self._q = a_new, v_new, q_new
        if (
            np.max(np.abs(v_new)) < self.cfg.rest_velocity
            and np.max(np.abs(a_new)) <= np.min(jdt)
        ):
            # from here the position is held: libfranka then sees v -> 0 (a change of at most
            # rest_velocity/dt in acceleration) and a -> 0 on the next cycle
            self.state = SupervisorState.HOLDING
        return self._q.copy()

    # -- measured-state watches ---------------------------------------------------------------
    def _hold(self, time: float, kind: str, message: str) -> None:
        """Hold with an alarm on a measured quantity (the first alarm of a run is the one kept;
        later excursions while already stopping on an alarm are not re-logged every cycle)."""
        if not self.alarm:
            self.raise_alarm(time, kind, f"{message}; holding")

    def _watch_joints(self, time: float, q_measured: Vec) -> None:
        c = self.cfg
        qm = np.ascontiguousarray(q_measured, dtype=np.float64)
        if qm.shape != (7,) or not math.isfinite(qm.sum()):
            self._hold(time, "joints_nonfinite", f"measured joints {np.array2string(qm, precision=3)} not finite")
            return
        j, room = nearest_limit(qm, self._lo, self._hi)
        if room < c.joint_stop_margin:
            if self.state is SupervisorState.RUNNING:
                self.raise_alarm(time, "joint_limit", f"joint {j + 1} measured {room:.4f} rad from its limit")
        elif room < c.joint_warn_margin:
            if not self._joint_warned:
                self.event(time, "joint_limit_near", f"joint {j + 1} measured {room:.4f} rad from its limit")
                self._joint_warned = True
        else:
            self._joint_warned = False

    def _watch_scope(self, time: float, rcm_error: float | None, depth: float | None, residual: Vec | None) -> None:
        c = self.cfg
        if rcm_error is not None and not (rcm_error <= c.max_rcm_error):  # NaN fails the test too
            self._hold(
                time, "rcm_error", f"measured RCM error {rcm_error * 1e3:.2f} mm > {c.max_rcm_error * 1e3:.2f} mm"
            )
        if depth is not None and not (c.depth_min <= depth <= c.depth_max):
            self._hold(
                time,
                "insertion_depth",
                f"measured insertion depth {depth * 1e3:.1f} mm outside "
                f"[{c.depth_min * 1e3:.1f}, {c.depth_max * 1e3:.1f}] mm",
            )
        if residual is not None:
            f = float(np.linalg.norm(np.asarray(residual, dtype=float)))
            over = not (f <= c.max_residual_force)
            if not over:
                self._residual_over_since = None
            elif self._residual_over_since is None:
                self._residual_over_since = time
            if over and (not math.isfinite(f) or time - self._residual_over_since >= c.residual_force_time - 1e-9):
                self._hold(
                    time,
                    "residual_force",
                    f"measured residual force |ΔF| {f:.1f} N > {c.max_residual_force:.1f} N"
                    f" for {(time - self._residual_over_since) * 1e3:.0f} ms",
                )

    def _watch_controller_stop(self, time: float, stopping: bool) -> None:
        if not stopping or self.state is not SupervisorState.RUNNING:
            return
        if self._controller_stop_since is None:
            self._controller_stop_since = time
            self.event(time, "rcm_infeasible", "the RCM task cannot be kept inside the joint limits; braking")
        at_rest = float(np.max(np.abs(self._v))) < 10.0 * self.cfg.rest_velocity
        if at_rest or time - self._controller_stop_since >= CONTROLLER_STOP_TIMEOUT:
            self._hold(time, "rcm_infeasible", "the RCM task could not be kept inside the joint limits")

    def _watch_deadline(self, time: float, compute_time: float) -> None:
        c = self.cfg
        if compute_time > c.cycle_budget:
            self.deadline_misses += 1
            self.consecutive_misses += 1
            self.counted_event(
                time, "deadline_miss", f"cycle compute {compute_time * 1e6:.0f} us > {c.cycle_budget * 1e6:.0f} us"
            )
            if c.max_consecutive_misses and self.consecutive_misses >= c.max_consecutive_misses:
                self.raise_alarm(time, "deadline", f"{self.consecutive_misses} consecutive deadline misses")
        else:
            self.consecutive_misses = 0

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
            compute_time: This cycle's compute time (s); None skips the deadline watch.
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
        self._watch_scope(time, rcm_error, depth, residual)
        self._watch_controller_stop(time, controller_stopping)

        if self.state is SupervisorState.HOLDING:
            q = self._q.copy()
            self._accept(q)
            return q
        if self.state is SupervisorState.STOPPING:
            return self._stop_step()
        problem = self.check_command(q_cmd)
        if problem is None:
            q = np.asarray(q_cmd, dtype=float)
            self._accept(q)
            return q.copy()
        kind, message = problem
        self.replaced_commands += 1
        self.raise_alarm(time, kind, f"{message}; replaced by a stop")
        return self._stop_step()
