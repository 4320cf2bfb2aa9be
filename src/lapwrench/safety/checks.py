"""The supervisor's compiled checks and its measurement of the scope at the measured joints.

* :func:`command_violation`: the first limit (position, velocity, acceleration, jerk) a joint
  command breaks after the history of commands sent, differentiated as libfranka does, or that the
  supervisor's stop begun from it would break (:func:`stop_reach`);
* :func:`nearest_limit`: the measured joint closest to one of its limits;
* :func:`measure_scope`: the RCM error and insertion depth at the robot's *measured* joints.

The first two are numba kernels (:func:`lapwrench.jit.kernel`), called every cycle by
:class:`~lapwrench.safety.supervisor.SafetySupervisor`; :func:`measure_scope` is called by every
control loop to feed the supervisor's measured-state watches.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from lapwrench.inputs import is_f64_c, real_array
from lapwrench.jit import bind, kernel
from lapwrench.rcm.geometry import axis_rcm_error_and_depth
from lapwrench.robot.model import RobotModel
from lapwrench.spatial import Vec


class MeasuredScope(NamedTuple):
    """The scope against the RCM point at the measured joints: ``rcm_error`` (m, distance from p_R
    to the scope axis, eq 27) and ``depth`` (m of scope tip beyond p_R along the shaft). A named tuple:
    one is made every control cycle."""

    rcm_error: float
    depth: float


def measure_scope(model: RobotModel, q_measured: Vec, p_R: Vec) -> MeasuredScope:
    """RCM error and insertion depth at the robot's *measured* joints, for the controller's p_R.

    One forward kinematics pass (:meth:`RobotModel.scope_axis_into`) and the formulas of
    :mod:`lapwrench.rcm.geometry`, about 10 µs. Non-finite joints or p_R propagate to NaN values,
    and arrays of the wrong shape or of values that are not real numbers give NaN (the supervisor then
    holds): a broken driver's reading is a hold, never a traceback in the loop.
    """
    q = q_measured if is_f64_c(q_measured) else real_array(q_measured)
    p = p_R if is_f64_c(p_R) else real_array(p_R)
    if q is None or p is None or q.shape != (model.nq,) or p.shape != (3,):
        return MeasuredScope(math.nan, math.nan)
    axis = model.scope_axis_into(q)  # the model's own arrays, used before its next evaluation
    e, depth = _axis_error_and_depth()(axis.p_E, axis.d_z, axis.P, p, float(model.length))
    return MeasuredScope(e, depth)


@functools.cache
def _axis_error_and_depth() -> Callable[[Vec, Vec, Vec, Vec, float], tuple[float, float]]:
    """:func:`axis_rcm_error_and_depth` through its entry point for C-contiguous float64 arrays
    (:func:`lapwrench.jit.bind`, bound at the first call): no type dispatch per cycle."""
    z = np.zeros(3)
    return bind(axis_rcm_error_and_depth, z, z, np.zeros((3, 3)), z, 0.0)


@kernel
def stop_reach(v: float, a: float, a_stop: float, j_stop: float, dt: float) -> tuple[float, float]:
    """Upper bounds of the peak speed (rad/s) and of the travel (rad) in the positive direction of the
    supervisor's stop (:meth:`~lapwrench.safety.supervisor.SafetySupervisor.stop`) begun at velocity ``v``
    and acceleration ``a`` of one joint, braking at ``a_stop`` with jerk ``j_stop``.

    An acceleration in that direction is first ramped out (the speed still grows by a²/(2 j_stop)
    meanwhile), then the speed v1 reached is braked, in at most the continuous jerk-limited distance
    v1²/(2 a_stop) + v1 a_stop/(2 j_stop); one more cycle at v1 covers the discretisation. Motion the
    other way counts as none. Why: a command inside every limit can still be one the stop cannot end
    inside them (full speed just short of a joint limit, or full acceleration at full speed); the
    supervisor refuses such a command (:func:`command_violation`), so its stop always can."""
    u = max(v, 0.0)
    b = max(a, 0.0)
    v1 = u + b * b / (2.0 * j_stop)
    return v1, v1 * (b / j_stop + v1 / (2.0 * a_stop) + a_stop / (2.0 * j_stop) + dt)


@kernel
def command_violation(
    q: Vec, q_prev: Vec, v_prev: Vec, a_prev: Vec, lo: Vec, hi: Vec, tol: float, v_max: Vec, a_max: Vec,
    j_max: Vec, stop_a: Vec, stop_j: Vec, dt: float,
) -> tuple[int, int, float]:
    """The first limit the command ``q`` breaks after the history (q, v, a) as libfranka differentiates
    it: (0 none | 1 position | 2 velocity | 3 acceleration | 4 jerk, joint, value), or that the stop
    begun from it (deceleration ``stop_a``, jerk ``stop_j``) would break (:func:`stop_reach`):
    (6 position, joint, where the stop would end | 7 velocity, joint, the stop's peak velocity)."""
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
    for j in range(n):
        up_speed, up = stop_reach(v[j], a[j], stop_a[j], stop_j[j], dt)
        down_speed, down = stop_reach(-v[j], -a[j], stop_a[j], stop_j[j], dt)
        if q[j] + up > hi[j] + tol:
            return 6, j, q[j] + up
        if q[j] - down < lo[j] - tol:
            return 6, j, q[j] - down
        if max(up_speed, down_speed) > v_max[j] * (1.0 + 1e-9):
            return 7, j, up_speed if up_speed >= down_speed else -down_speed
    return 0, 0, 0.0


@kernel
def accept_command(
    q: Vec, history: np.ndarray, lo: Vec, hi: Vec, tol: float, v_max: Vec, a_max: Vec, j_max: Vec, stop_a: Vec,
    stop_j: Vec, dt: float,
) -> tuple[int, int, float]:
    """:func:`command_violation` of ``q`` after ``history`` (rows: the last command sent, its velocity
    and acceleration), code 5 if ``q`` is not finite; with no violation (code 0) ``q`` is accepted:
    ``history`` becomes (q, v, a) as libfranka differentiates it, in place. The supervisor's check
    and bookkeeping of a passing command in one call."""
    n = q.shape[0]
    for j in range(n):
        if not math.isfinite(q[j]):
            return 5, j, q[j]
    code, jw, value = command_violation(
        q, history[0], history[1], history[2], lo, hi, tol, v_max, a_max, j_max, stop_a, stop_j, dt
    )
    if code == 0:
        for j in range(n):
            v = (q[j] - history[0, j]) / dt
            history[2, j] = (v - history[1, j]) / dt
            history[1, j] = v
            history[0, j] = q[j]
    return code, jw, value


@kernel
def measured_joints_room(q: Vec, lo: Vec, hi: Vec) -> tuple[bool, int, float]:
    """(every measured joint finite, the joint nearest to one of its limits, its room in rad)."""
    for j in range(q.shape[0]):
        if not math.isfinite(q[j]):
            return False, 0, math.nan
    jm, room = nearest_limit(q, lo, hi)
    return True, jm, room


@kernel
def nearest_limit(q: Vec, lo: Vec, hi: Vec) -> tuple[int, float]:
    """The joint nearest to one of its limits and its room (rad)."""
    jm, room = 0, np.inf
    for j in range(q.shape[0]):
        r = min(q[j] - lo[j], hi[j] - q[j])
        if r < room:
            jm, room = j, r
    return jm, room


@kernel
def measured_step(q: Vec, q_prev: Vec) -> tuple[int, float]:
    """The measured joint that moved most since the previous reading ``q_prev`` and by how much (rad);
    ``q_prev`` becomes ``q``, in place (one compiled call per cycle, no temporary arrays)."""
    jm, step = 0, 0.0
    for j in range(q.shape[0]):
        d = abs(q[j] - q_prev[j])
        if d > step:
            jm, step = j, d
        q_prev[j] = q[j]
    return jm, step
