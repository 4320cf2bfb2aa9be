"""The compiled tick around the cues that run in Python (plugins): two calls, with little crossing between.

The Python cues read the tick's :class:`~lapwrench.robot.model.Kinematics` and
:class:`~lapwrench.rcm.geometry.TaskGeometry`. Handing those named tuples of arrays from numba to
Python, and back into the motion stage, costs about as much as the maths that makes them (every
array that crosses is a new object each way, 0.5-1 µs under load). So both live in one buffer the
controller allocates once (:func:`front_size`) and cuts into views once (:func:`front_views`):
:func:`front_into` writes the tick up to the cues there (:func:`~lapwrench.tick_core.tick_front`),
the cues read the same views, and :func:`motion_tail_from` reads them back inside the compiled code
for :func:`~lapwrench.tick_core.motion_tail`. Only the buffer and a few numbers cross.

The views hold this tick's values until the next tick writes the buffer: what must outlive the tick
is copied (:func:`front_into` returns e_R, p_R, p_G, F_re⊥ and ΔF in a new array).
"""

from __future__ import annotations

import numpy as np

from lapwrench.jit import kernel
from lapwrench.rcm.adaptive import AdaptiveParams, AdaptiveState
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics, KinematicTerms
from lapwrench.spatial import Mat, Vec
from lapwrench.tick_core import MotionTail, SaturationInputs, motion_tail, tick_front
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.ft_zero import FtTare

# The arguments of the entry points (tick_stage, front_into, motion_tail_from) in their order, as the controller
# packs them (lapwrench.compiled_tick). The readings: F/T force, torque, valid; tactile values, valid; image
# points. The state: the terms, the adaptive RCM state and parameters, the robot's force estimate and whether
# it has one, the measured-feedback offsets, {E}'s measured placement and whether it is measured.
ReadingArgs = tuple[Vec, Vec, bool, Vec, bool, Mat]
StateArgs = tuple[KinematicTerms, AdaptiveState, AdaptiveParams, Vec, bool, Vec, Mat, Vec, bool]
FrontArgs = tuple[*StateArgs, Vec, Vec, bool, Vec, bool, FtTare, TickParams]  # front_into without the buffer
TickArgs = tuple[*StateArgs, *ReadingArgs, Vec, bool, Mat, bool, SaturationInputs, FtTare, TickParams]
MotionArgs = tuple[
    Vec, float, *ReadingArgs, Mat, Mat, Mat, Vec, Vec, bool, Mat, float, bool, SaturationInputs, TickParams
]


@kernel
def front_size(n: int) -> int:
    """Floats in the buffer of :func:`front_views` for an ``n``-joint robot."""
    return n * n + 19 * n + 75


@kernel
def front_views(buf: Vec, n: int, s_star: float) -> tuple[Kinematics, TaskGeometry]:
    """``buf`` (:func:`front_size` floats) cut into the tick's kinematics and geometry, disjoint views in
    field order; ``s_star`` (s*, eq 34) is the geometry's one number, which a buffer does not hold."""
    q, dq = buf[0:n], buf[n:2 * n]
    M = buf[2 * n:2 * n + n * n].reshape((n, n))
    at = 2 * n + n * n
    nle, gravity = buf[at:at + n], buf[at + n:at + 2 * n]
    at += 2 * n
    J_E = buf[at:at + 6 * n].reshape((6, n))
    at += 6 * n
    J_R = buf[at:at + 3 * n].reshape((3, n))
    at += 3 * n
    J_G = buf[at:at + 6 * n].reshape((6, n))
    at += 6 * n  # then the 3-vectors and the 3 x 3 matrices
    kin = Kinematics(
        q, dq, M, nle, gravity, buf[at:at + 3], buf[at + 3:at + 12].reshape((3, 3)), J_E, buf[at + 12:at + 15],
        buf[at + 15:at + 24].reshape((3, 3)), buf[at + 24:at + 27], buf[at + 27:at + 36].reshape((3, 3)),
        buf[at + 36:at + 39], buf[at + 39:at + 48].reshape((3, 3)), buf[at + 48:at + 54],
    )
    at += 54
    geo = TaskGeometry(
        buf[at:at + 3], buf[at + 3:at + 6], buf[at + 6:at + 9], buf[at + 9:at + 12], J_R, s_star,
        buf[at + 12:at + 15], buf[at + 15:at + 18], J_G, buf[at + 18:at + 21],
    )
    return kin, geo


@kernel
def front_into(
    terms: KinematicTerms, rcm: AdaptiveState, adaptive: AdaptiveParams, ext_force: Vec, has_ext: bool, offsets: Vec,
    R_measured: Mat, p_measured: Vec, has_measured: bool, ft_force: Vec, ft_torque: Vec, has_ft: bool, tactile: Vec,
    has_tactile: bool, tare: FtTare, p: TickParams, buf: Vec,
) -> tuple[Mat, float, bool]:
    """:func:`~lapwrench.tick_core.tick_front` written into ``buf`` (:func:`front_views`).

    Returns new ``vec3`` rows [e_R, p_R, p_G, F_re⊥, ΔF, the hand's force, its torque] (the last two the
    conditioned F/T reading the cues read), s* and whether ΔF is valid (eq 19: the F/T and the robot's
    estimate both)."""
    k, g, F_lat, residual, has_residual, force, torque = tick_front(
        terms, rcm, adaptive, ext_force, has_ext, offsets, R_measured, p_measured, has_measured, ft_force, ft_torque,
        has_ft, tactile, has_tactile, tare, p,
    )
    kin, geo = front_views(buf, k.q.shape[0], g.s_star)
    kin.q[:], kin.dq[:], kin.M[:], kin.nle[:], kin.gravity[:] = k.q, k.dq, k.M, k.nle, k.gravity
    kin.p_E[:], kin.R_E[:], kin.J_E[:], kin.p_H[:], kin.R_H[:] = k.p_E, k.R_E, k.J_E, k.p_H, k.R_H
    kin.p_C[:], kin.R_C[:], kin.d_z[:], kin.P[:], kin.a_E[:] = k.p_C, k.R_C, k.d_z, k.P, k.a_E
    geo.p_R[:], geo.rcm_velocity[:], geo.e_R[:], geo.e_R_rate[:] = g.p_R, g.rcm_velocity, g.e_R, g.e_R_rate
    geo.J_R[:], geo.p_G[:], geo.o_G[:], geo.J_G[:], geo.e_R_offset[:] = g.J_R, g.p_G, g.o_G, g.J_G, g.e_R_offset
    rows = (g.e_R, g.p_R, g.p_G, F_lat, residual, force, torque)
    vec3 = np.empty((len(rows), 3))
    for i, row in enumerate(rows):
        vec3[i] = row
    return vec3, g.s_star, has_residual


@kernel
def motion_tail_from(
    buf: Vec, s_star: float, ft_force: Vec, ft_torque: Vec, has_ft: bool, tactile: Vec, has_tactile: bool,
    points: Mat, extra_W: Mat, extra_points: Mat, extra_D: Mat, extra_task_F: Vec, ddq_ref: Vec, stopping: bool,
    R_E0: Mat, depth_offset: float, may_admit: bool, sat: SaturationInputs, p: TickParams,
) -> MotionTail:
    """:func:`~lapwrench.tick_core.motion_tail` on the kinematics and geometry :func:`front_into` wrote
    into ``buf`` (with s* = ``s_star``); returns what it returns."""
    kin, geo = front_views(buf, ddq_ref.shape[0], s_star)
    return motion_tail(
        kin, geo, ft_force, ft_torque, has_ft, tactile, has_tactile, points, extra_W, extra_points, extra_D,
        extra_task_F, ddq_ref, stopping, R_E0, depth_offset, may_admit, sat, p,
    )
