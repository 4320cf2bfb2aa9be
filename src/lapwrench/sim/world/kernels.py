"""The per-tick glue of :class:`~lapwrench.sim.world.SimWorld` as compiled kernels, and the constants they read.

One tick: :func:`_begin_tick` checks the references and writes the servo set points,
:func:`_substep_torque` accumulates the tick mean of the link-side joint torque after every physics
substep, :func:`_end_tick` runs the stability checks and remembers the state of the closing
``mj_forward``; :func:`_weld_force` reads the trocar weld's contact force. They run on views of
``MjData`` that the world binds once at construction (:func:`lapwrench.jit.bind`).

The constants live here because numba freezes them into the kernels' machine code (see
:mod:`lapwrench.jit`): :data:`CONTROL_DT`, the kernels' return codes and the rows of the per-joint
constant and work tables they are passed.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from lapwrench.jit import kernel
from lapwrench.spatial import all_finite

CONTROL_DT = 0.001

# MuJoCo's mjMAXVAL: mj_checkPos/mj_checkVel reset the state on a value beyond it (or NaN).
_MJ_MAXVAL = 1e10
_EQUALITY = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)

# Return codes of the tick kernels.
_OK_REUSE = 0  # state unchanged since the last mj_forward: the first substep may run mj_step2 only
_OK_FULL = 1  # state changed: the first substep runs the full mj_step
_BAD_Q_REF = 2
_BAD_DQ_REF = 3
_BAD_STATE = 4
_BAD_WARNING = 5
_BAD_DEPTH = 6
_BAD_FORCE = 7


# Rows of the per-joint constant table and of the tick's work table (arguments of the kernels).
_C_KV_OVER_KP, _C_KV, _C_TAU_FREE, _C_DAMPING, _C_ARMATURE = range(5)
_W_Q_REF_PREV, _W_V_TICK, _W_V_START, _W_TOTAL, _W_TAU_MEAN = range(5)


@kernel
def _same_and_sane(a: np.ndarray, b: np.ndarray, start: int) -> bool:
    """a == b[start : start + a.size] element for element (NaN never equal), no |a| above mjMAXVAL."""
    for i in range(a.size):  # noqa: SIM110
        if not (a[i] == b[start + i] and abs(a[i]) <= _MJ_MAXVAL):
            return False
    return True


@kernel
def _begin_tick(
    q_ref: np.ndarray,
    dq_ref: np.ndarray,
    use_dq_ref: bool,
    fwd_valid: bool,
    const: np.ndarray,
    work: np.ndarray,
    idx: np.ndarray,
    ctrl: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    mocap_pos: np.ndarray,
    mocap_quat: np.ndarray,
    mocap_matters: bool,
    eq_active: np.ndarray,
    fwd: np.ndarray,
) -> int:
    """Check the references, write the servo set points, start the tick's torque sums.

    ctrl = q_ref + kv/kp dq_ref (the actuator force kp ctrl - kp q - kv dq is then the PD law),
    with dq_ref the finite difference of the references when not given. ``idx``: rows actuator
    ids and dof addresses of the arm joints; ``fwd``: the state at the last ``mj_forward``
    (qpos, qvel, mocap_pos, mocap_quat, eq_active, concatenated). Returns a ``_BAD_*`` code
    (nothing written for a bad reference), or ``_OK_REUSE`` when the position/velocity stages of
    the last ``mj_forward`` still hold for the current state, else ``_OK_FULL``.
    """
    n = q_ref.size
    if not all_finite(q_ref):
        return _BAD_Q_REF
    if use_dq_ref and not all_finite(dq_ref):
        return _BAD_DQ_REF
    q_prev = work[_W_Q_REF_PREV]
    kv_over_kp = const[_C_KV_OVER_KP]
    for i in range(n):
        dq = dq_ref[i] if use_dq_ref else (q_ref[i] - q_prev[i]) / CONTROL_DT
        ctrl[idx[0, i]] = q_ref[i] + kv_over_kp[i] * dq
        q_prev[i] = q_ref[i]
    if not (all_finite(qpos) and all_finite(qvel)):
        return _BAD_STATE
    for i in range(n):
        v = qvel[idx[1, i]]
        work[_W_V_TICK, i] = v
        work[_W_V_START, i] = v
        work[_W_TOTAL, i] = 0.0
    if not fwd_valid:
        return _OK_FULL
    k = 0
    if not _same_and_sane(qpos, fwd, k):
        return _OK_FULL
    k += qpos.size
    if not _same_and_sane(qvel, fwd, k):
        return _OK_FULL
    k += qvel.size
    if mocap_matters and not (
        _same_and_sane(mocap_pos, fwd, k) and _same_and_sane(mocap_quat, fwd, k + mocap_pos.size)
    ):
        return _OK_FULL
    k += mocap_pos.size + mocap_quat.size
    for i in range(eq_active.size):
        if eq_active[i] != fwd[k + i]:
            return _OK_FULL
    return _OK_REUSE


@kernel
def _substep_torque(
    qfrc_actuator: np.ndarray,
    qfrc_damper: np.ndarray,
    qvel: np.ndarray,
    idx: np.ndarray,
    const: np.ndarray,
    work: np.ndarray,
    last: bool,
    n_substeps: int,
    tick: float,
) -> None:
    """Add the substep just taken to the tick's torque sum; after the ``last`` one, write the tick mean
    of the link-side torque into its ``work`` row.

    The servo plus joint damping torque as ``implicitfast`` applied them over the substep: their
    velocity terms act at the end-of-substep velocity, -(kv + b) dv on top of the values at its start,
    except on a servo clipped at tau_max (then its torque does not depend on velocity)."""
    for i in range(idx.shape[1]):
        a = idx[1, i]
        v = qvel[a]
        tau = qfrc_actuator[a]
        kv = const[_C_KV, i] if abs(tau) < const[_C_TAU_FREE, i] else 0.0  # clipped: no velocity term
        work[_W_TOTAL, i] += tau + qfrc_damper[a] - (kv + const[_C_DAMPING, i]) * (v - work[_W_V_START, i])
        work[_W_V_START, i] = v
        if last:
            work[_W_TAU_MEAN, i] = (
                work[_W_TOTAL, i] / n_substeps - const[_C_ARMATURE, i] * (v - work[_W_V_TICK, i]) / tick
            )


@kernel
def _weld_force(efc_type: np.ndarray, efc_id: np.ndarray, efc_force: np.ndarray, weld: int, out: np.ndarray) -> None:
    """-efc_force of the first three constraint rows of equality ``weld`` (zeros if it has fewer)."""
    k = 0
    for i in range(efc_force.size):
        if efc_type[i] == _EQUALITY and efc_id[i] == weld:
            out[k] = -efc_force[i]
            k += 1
            if k == 3:
                return
    for i in range(3):
        out[i] = 0.0


@kernel
def _end_tick(
    warn_number: np.ndarray,
    warn: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    xpos: np.ndarray,
    xmat: np.ndarray,
    ids: np.ndarray,
    depth_range: np.ndarray,
    max_contact_force: float,
    efc_type: np.ndarray,
    efc_id: np.ndarray,
    efc_force: np.ndarray,
    mocap_pos: np.ndarray,
    mocap_quat: np.ndarray,
    eq_active: np.ndarray,
    fwd: np.ndarray,
) -> int:
    """The stability checks of a tick, in ``SimWorld._check``'s order; on success, remember the
    state this ``mj_forward`` was evaluated at (for the next tick's first substep).

    ``warn``: rows warning indices and their counts so far; ``ids``: body lap_E, body incision,
    the trocar weld; ``depth_range``: the insertion depths (exclusive) the trocar model holds.
    """
    for i in range(warn.shape[1]):
        if warn_number[warn[0, i]] != warn[1, i]:
            return _BAD_WARNING
    if not (all_finite(qpos) and all_finite(qvel)):
        return _BAD_STATE
    body_E, body_incision = ids[0], ids[1]
    depth = 0.0
    for k in range(3):  # (incision - p_E) . z_E
        depth += (xpos[body_incision, k] - xpos[body_E, k]) * xmat[body_E, 3 * k + 2]
    if not (depth_range[0] < depth < depth_range[1]):
        return _BAD_DEPTH
    f = np.zeros(3)
    _weld_force(efc_type, efc_id, efc_force, ids[2], f)
    if not (math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) <= max_contact_force):
        return _BAD_FORCE
    k = 0
    fwd[k : k + qpos.size] = qpos
    k += qpos.size
    fwd[k : k + qvel.size] = qvel
    k += qvel.size
    fwd[k : k + mocap_pos.size] = mocap_pos
    k += mocap_pos.size
    fwd[k : k + mocap_quat.size] = mocap_quat
    k += mocap_quat.size
    for i in range(eq_active.size):
        fwd[k + i] = eq_active[i]
    return _OK_REUSE
