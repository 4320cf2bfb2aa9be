"""The supervisor's event log, alarm latch and measured-state watches (issue 9).

:class:`SupervisorWatches` is the base of :class:`~lapwrench.safety.supervisor.SafetySupervisor`:
it records structured events (:attr:`~SupervisorWatches.events`, bounded, and
:attr:`~SupervisorWatches.pending`, drained by the logger each cycle), latches the first alarm and
switches to a stop, and watches what the caller measured, the same in the simulation and on the
robot. Each watch holds the arm (the supervisor's smooth, jerk-limited stop) with an alarm naming
the quantity and its value:

* ``rcm_error``, ``insertion_depth``, ``residual_force``, ``joints_nonfinite``: the measured RCM
  error, insertion depth, residual |ΔF| (eq 19) and joints against :class:`SupervisorConfig`; a
  non-finite value, or one that is not a real number, holds too;
* ``joints_jump``: a measured joint that moved more than ``max_joint_step`` a cycle since the previous
  reading (a corrupt reading: no arm moves that fast); a reading that comes late (by the session clock) may
  have moved that much for each cycle since, up to :data:`MAX_GAP_CYCLES`;
* **joint limits**: a *measured* joint closer than ``joint_warn_margin`` to a limit logs an event,
  closer than ``joint_stop_margin`` stops with an alarm (also during a stop begun without one);
* **deadlines**: a cycle over ``cycle_budget`` is a deadline miss (counted, logged with rate
  limiting); ``max_consecutive_misses`` in a row stop with an alarm;
* **controller stop**: a controller braking because the RCM task left the joint limits may reach
  rest (or run for :data:`CONTROLLER_STOP_TIMEOUT`), then the arm holds.

The durations (the residual force's ``residual_force_time``, the controller stop's timeout) count the
cycles as well as the caller's clock, whichever is longer (:meth:`SupervisorWatches.lasted`): a
stale, backward or NaN session time cannot keep a watch from firing.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from lapwrench.inputs import is_f64_c, real_array
from lapwrench.safety.checks import measured_joints_room, measured_step, nearest_limit
from lapwrench.safety.config import SupervisorConfig, SupervisorEvent, SupervisorState
from lapwrench.spatial import Vec

# Seconds a braking controller (TickResult.rcm_infeasible) may take to reach rest before the hold.
CONTROLLER_STOP_TIMEOUT = 1.0
# The most cycles of motion a late measured reading is allowed (joints_jump): libfranka ends the motion after
# about 20 missed cycles in a row, so a longer gap is no late cycle.
MAX_GAP_CYCLES = 20.0


def real_scalar(x: object) -> float:
    """``x`` as a float if it is one real number (an int, a float or a one-element array of them), else
    NaN: a measured value that is text, a boolean, complex or several values counts as not measured
    correctly, which every watch treats as out of bounds (before, text raised a TypeError in the gate)."""
    if type(x) is float:
        return x  # the common case
    a = real_array(x)
    if a is None or a.size != 1:
        return math.nan
    return float(a.reshape(()))


def _rate_limited(count: int) -> bool:
    """Log the first 10 occurrences, then every 1000th."""
    return count <= 10 or count % 1000 == 0


class SupervisorWatches:
    """Events, the alarm latch and the measured-state watches of the safety supervisor.

    Args:
        config: Thresholds (:class:`SupervisorConfig`).
        lo: Lower joint position limits (rad).
        hi: Upper joint position limits (rad).
    """

    _v: Vec  # velocity of the last command sent, kept by the SafetySupervisor subclass
    dt: float  # the control period (s), set by the SafetySupervisor subclass

    def __init__(self, config: SupervisorConfig, lo: Vec, hi: Vec) -> None:
        self.cfg = config
        self._lo = np.ascontiguousarray(lo, dtype=float)  # the compiled checks' argument type
        self._hi = np.ascontiguousarray(hi, dtype=float)
        self._nearest_limit = nearest_limit  # the subclass binds these to their argument types
        self._joints_room = measured_joints_room
        self._measured_step = measured_step
        self._q_measured_prev = np.zeros_like(self._lo)  # the previous measured joints ...
        self._q_measured_seen = False  # ... if there was one (not since start, nor since a cycle without)
        self._q_measured_time = 0.0  # ... and its session time
        self.events: deque[SupervisorEvent] = deque(maxlen=config.max_events)
        self.pending: list[SupervisorEvent] = []
        self.state = SupervisorState.HOLDING
        self.alarm = False
        self.alarm_reason: str | None = None
        self.deadline_misses = 0
        self.consecutive_misses = 0
        self._counts: dict[str, int] = {}
        self._joint_warned = False
        self._residual_over_since: float | None = None
        self._residual_over_cycles = 0
        self._controller_stop_since: float | None = None
        self._controller_stop_cycles = 0

    # -- events and the alarm -----------------------------------------------------------------
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

    def lasted(self, since: float, cycles: int, time: float) -> float:
        """How long (s) a condition first seen at session time ``since`` has lasted at ``time``, ``cycles``
        cycles later: the longer of the clock's and the cycles' count. Each :meth:`filter` call is one
        control period, so the count cannot be fooled by a stale, backward or NaN clock, which alone
        would keep a timed watch (residual force, controller stop) from ever firing."""
        by_cycles = cycles * self.dt
        by_clock = time - since
        return by_clock if by_clock > by_cycles else by_cycles  # a NaN clock compares False: the count

    # -- measured-state watches ---------------------------------------------------------------
    def _hold(self, time: float, kind: str, message: str) -> None:
        """Hold with an alarm on a measured quantity (the first alarm of a run is the one kept;
        later excursions while already stopping on an alarm are not re-logged every cycle)."""
        if not self.alarm:
            self.raise_alarm(time, kind, f"{message}; holding")

    def _watch_joints(self, time: float, q_measured: Vec) -> None:
        c = self.cfg
        qm: np.ndarray | None = q_measured
        if not is_f64_c(qm):
            qm = real_array(q_measured)
        if qm is None:
            self._q_measured_seen = False
            self._hold(time, "joints_nonfinite", f"measured joints {q_measured!r:.80} are not real numbers")
            return
        if qm.shape != self._lo.shape:
            self._q_measured_seen = False
            self._hold(time, "joints_nonfinite", f"measured joints have shape {qm.shape}, expected {self._lo.shape}")
            return
        finite, j, room = self._joints_room(qm, self._lo, self._hi)
        if not finite:
            self._q_measured_seen = False
            self._hold(time, "joints_nonfinite", f"measured joints {np.array2string(qm, precision=3)} not finite")
            return
        if room < c.joint_stop_margin:
            if not self.alarm:  # also during a stop begun without an alarm: a measured limit is a fault
                self.raise_alarm(time, "joint_limit", f"joint {j + 1} measured {room:.4f} rad from its limit")
        elif room < c.joint_warn_margin:
            if not self._joint_warned:
                self.event(time, "joint_limit_near", f"joint {j + 1} measured {room:.4f} rad from its limit")
                self._joint_warned = True
        else:
            self._joint_warned = False
        seen, self._q_measured_seen = self._q_measured_seen, True
        cycles = (time - self._q_measured_time) / self.dt  # since the previous reading, by the clock
        self._q_measured_time = time
        js, step = self._measured_step(qm, self._q_measured_prev)  # the previous reading becomes this one
        # a late reading (a late cycle) may have moved further: up to MAX_GAP_CYCLES cycles' worth
        allowed = c.max_joint_step * (min(max(cycles, 1.0), MAX_GAP_CYCLES) if math.isfinite(cycles) else 1.0)
        if seen and step > allowed:
            span = f"{cycles:.3g} cycles" if cycles > 1.5 else "one cycle"  # NaN compares False
            self._hold(time, "joints_jump", f"measured joint {js + 1} moved {step:.4f} rad in {span}"
                                            f" (> {allowed:.4f}): a corrupt reading")

    def _watch_scope(self, time: float, rcm_error: float | None, depth: float | None, residual: Vec | None) -> None:
        c = self.cfg
        rcm_error = None if rcm_error is None else real_scalar(rcm_error)
        depth = None if depth is None else real_scalar(depth)
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
            r = residual if is_f64_c(residual) else real_array(residual)
            if r is None:
                self._hold(time, "residual_force", f"measured residual force {residual!r:.80} is not real numbers")
                return
            if r.shape != (3,):  # ΔF is a force: a wrench or a matrix here is a wiring fault, not a force
                self._hold(time, "residual_force", f"measured residual force has shape {r.shape}, expected 3 values")
                return
            f = math.hypot(r[0], r[1], r[2])  # no overflow (and no warning) for huge finite values
            over = not (f <= c.max_residual_force)
            since = self._residual_over_since
            if not over:
                self._residual_over_since = None
                return
            if since is None:
                since = self._residual_over_since = time
                self._residual_over_cycles = 0
            else:
                self._residual_over_cycles += 1
            lasted = self.lasted(since, self._residual_over_cycles, time)
            if not math.isfinite(f) or lasted >= c.residual_force_time - 1e-9:
                self._hold(
                    time,
                    "residual_force",
                    f"measured residual force |ΔF| {f:.1f} N > {c.max_residual_force:.1f} N for {lasted * 1e3:.0f} ms",
                )

    def _watch_controller_stop(self, time: float, stopping: bool) -> None:
        if not stopping or self.state is not SupervisorState.RUNNING:
            return
        if self._controller_stop_since is None:
            self._controller_stop_since, self._controller_stop_cycles = time, 0
            self.event(time, "rcm_infeasible", "the RCM task cannot be kept inside the joint limits; braking")
        else:
            self._controller_stop_cycles += 1
        at_rest = float(np.max(np.abs(self._v))) < 10.0 * self.cfg.rest_velocity
        lasted = self.lasted(self._controller_stop_since, self._controller_stop_cycles, time)
        if at_rest or lasted >= CONTROLLER_STOP_TIMEOUT - 1e-9:
            self._hold(time, "rcm_infeasible", "the RCM task could not be kept inside the joint limits")

    def _watch_deadline(self, time: float, compute_time: float) -> None:
        c = self.cfg
        compute_time = real_scalar(compute_time)
        if not compute_time <= c.cycle_budget:  # a NaN compute time is a miss: it was not measured in time
            self.deadline_misses += 1
            self.consecutive_misses += 1
            self.counted_event(
                time, "deadline_miss", f"cycle busy time {compute_time * 1e6:.0f} us > {c.cycle_budget * 1e6:.0f} us"
            )
            # once, when the run of misses reaches the bound: a miss in every cycle of the stop that follows
            # is counted above, not another alarm event per millisecond (which would flood the log)
            if c.max_consecutive_misses and self.consecutive_misses == c.max_consecutive_misses:
                self.raise_alarm(time, "deadline", f"{self.consecutive_misses} consecutive deadline misses")
        else:
            self.consecutive_misses = 0
