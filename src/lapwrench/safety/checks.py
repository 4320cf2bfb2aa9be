"""The supervisor's compiled checks and its measurement of the scope at the measured joints.

* :func:`command_violation`: the first limit (position, velocity, acceleration, jerk) a joint
  command breaks after the history of commands sent, differentiated as libfranka does;
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
    :mod:`lapwrench.rcm.geometry`, about 10 µs. Non-finite joints or p_R propagate to NaN values
    and arrays of the wrong shape give NaN (the supervisor then holds).
    """
    q = q_measured if type(q_measured) is np.ndarray else np.asarray(q_measured, dtype=float)
    p = p_R if _is_f64_c(p_R) else np.ascontiguousarray(p_R, dtype=float)
    if q.shape != (model.nq,) or p.shape != (3,):
        return MeasuredScope(math.nan, math.nan)
    axis = model.scope_axis_into(q)  # the model's own arrays, used before its next evaluation
    e, depth = _axis_error_and_depth()(axis.p_E, axis.d_z, axis.P, p, float(model.length))
    return MeasuredScope(e, depth)


def _is_f64_c(x: object) -> bool:
    """``x`` is a C-contiguous float64 array (passed to a bound kernel as it is)."""
    return type(x) is np.ndarray and x.dtype == np.float64 and x.flags.c_contiguous


@functools.cache
def _axis_error_and_depth() -> Callable[[Vec, Vec, Vec, Vec, float], tuple[float, float]]:
    """:func:`axis_rcm_error_and_depth` through its entry point for C-contiguous float64 arrays
    (:func:`lapwrench.jit.bind`, bound at the first call): no type dispatch per cycle."""
    z = np.zeros(3)
    return bind(axis_rcm_error_and_depth, z, z, np.zeros((3, 3)), z, 0.0)


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
def accept_command(
    q: Vec, history: np.ndarray, lo: Vec, hi: Vec, tol: float, v_max: Vec, a_max: Vec, j_max: Vec, dt: float,
) -> tuple[int, int, float]:
    """:func:`command_violation` of ``q`` after ``history`` (rows: the last command sent, its velocity
    and acceleration), code 5 if ``q`` is not finite; with no violation (code 0) ``q`` is accepted:
    ``history`` becomes (q, v, a) as libfranka differentiates it, in place. The supervisor's check
    and bookkeeping of a passing command in one call."""
    n = q.shape[0]
    for j in range(n):
        if not math.isfinite(q[j]):
            return 5, j, q[j]
    code, jw, value = command_violation(q, history[0], history[1], history[2], lo, hi, tol, v_max, a_max, j_max, dt)
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
