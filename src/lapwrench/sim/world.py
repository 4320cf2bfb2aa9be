"""The robot in the loop: a Franka-like joint position servo driving the MuJoCo world.

Timing: the controller ticks at 1 kHz (:meth:`SimWorld.step`); each tick runs
``round(1 ms / timestep)`` physics steps (default timestep 0.5 ms, i.e. 2 substeps) with the
``implicitfast`` integrator, so the actuator damping is integrated implicitly. The joint servo
torque is recomputed by MuJoCo at every substep (a continuous-time analogue of the Franka's internal
joint impedance loop):

    tau_J = Kp (q_ref - q) + Kd (dq_ref - dq) + g(q),   clipped to tau_max = (87 x 4, 12 x 3) N m,

where g(q) is MuJoCo's gravity compensation of the arm and laparoscope. When no ``dq_ref`` is given
it is the finite difference of successive references, as the robot does with its command stream.

After the substeps the forward dynamics is evaluated once more (``mj_forward``), so every reading
(poses, contact force, torques, accelerations) is consistent with the state at :attr:`SimWorld.time`.

Within a tick the servo torque is a sawtooth: the reference steps at the tick, then the PD term
decays as the joint catches up (by about Kp q̇ dt per tick, several N m at 1 rad/s). A sample at the
end of the tick is therefore biased against the torque that actually moved the arm during it.
:meth:`SimWorld.joint_torque_tick_mean` is the tick mean of the link-side torque, with each
substep's velocity-dependent terms (servo damping, joint damping) at the velocity the implicit
integrator used: what a torque sensor averaged over the 1 ms sample delivers, and consistent with
the momentum change over the tick.

Cost: the per-tick glue (reference check, servo references, the tick-mean torque, the stability
checks, the contact force) runs in small numba kernels on views of ``MjData`` cached at
construction, bound to their argument types there (no per-call dispatch, nothing compiles in the
loop), so a tick costs little more than MuJoCo's own work. The position and velocity stages
of the tick's first substep are those of the previous tick's closing ``mj_forward`` whenever the
state they depend on (qpos, qvel, the equality activations and, unless they are inert, the mocap
poses) is unchanged since then, so that substep runs ``mj_step2`` only: bit for bit the same
trajectory as ``mj_step``, one position/velocity pass (about half a physics step) cheaper. After
changing the *model's* physics parameters between two ticks, call ``mujoco.mj_forward`` on
:attr:`SimWorld.data` (as before ``mj_step2``) or :meth:`SimWorld.reset`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from lapwrench.jit import bind, kernel
from lapwrench.robot.description import FRAME_C, FRAME_E, FRAME_H
from lapwrench.robot.errors import RobotError
from lapwrench.sim.scene.arm import TAU_MAX
from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.scene.instruments import instrument_pose_through_port
from lapwrench.sim.scene.names import (
    CAMERA_NAME,
    HOUSING_BODY,
    HOUSING_JOINTS,
    INCISION_BODY,
    INCISION_JOINTS,
    INSTRUMENT_BODIES,
    INSTRUMENT_TIP_SITES,
    PORT_SITES,
    TROCAR_BODY,
    TROCAR_WELD,
)

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


@kernel
def _all_finite(x: np.ndarray) -> bool:
    """``np.all(np.isfinite(x))`` for a 1-D array."""
    for v in x:  # noqa: SIM110 (a plain loop compiles to the tightest code)
        if not math.isfinite(v):
            return False
    return True


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
    if not _all_finite(q_ref):
        return _BAD_Q_REF
    if use_dq_ref and not _all_finite(dq_ref):
        return _BAD_DQ_REF
    q_prev = work[_W_Q_REF_PREV]
    kv_over_kp = const[_C_KV_OVER_KP]
    for i in range(n):
        dq = dq_ref[i] if use_dq_ref else (q_ref[i] - q_prev[i]) / CONTROL_DT
        ctrl[idx[0, i]] = q_ref[i] + kv_over_kp[i] * dq
        q_prev[i] = q_ref[i]
    if not (_all_finite(qpos) and _all_finite(qvel)):
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
    if not (_all_finite(qpos) and _all_finite(qvel)):
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


def _slice_if_contiguous(idx: np.ndarray) -> slice | np.ndarray:
    """``slice(a, a + n)`` when ``idx`` is a run of consecutive indices (views), else ``idx``."""
    a = int(idx[0])
    return slice(a, a + len(idx)) if np.array_equal(idx, np.arange(a, a + len(idx))) else idx


def _mocap_is_inert(m: mujoco.MjModel) -> bool:
    """True when no mocap pose can change the dynamics: the mocap subtrees have no joints and no
    colliding geoms, and no constraint, tendon, flex or actuator refers to them."""
    if m.nmocap == 0:
        return True
    if m.ntendon or m.nflex:
        return False
    inside = np.zeros(m.nbody, bool)
    for b in range(1, m.nbody):  # parents come before children
        inside[b] = m.body_mocapid[b] >= 0 or inside[m.body_parentid[b]]
    if np.any(inside[m.jnt_bodyid]):
        return False
    contacts_on = not (m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT)
    geoms = np.flatnonzero(inside[m.geom_bodyid])
    if contacts_on and np.any((m.geom_contype[geoms] != 0) | (m.geom_conaffinity[geoms] != 0)):
        return False
    site_inside = inside[m.site_bodyid]
    geom_inside = inside[m.geom_bodyid]
    obj = mujoco.mjtObj

    def refers(objtype: int, objid: int) -> bool:
        if objid < 0:
            return False
        if objtype in (int(obj.mjOBJ_BODY), int(obj.mjOBJ_XBODY)):
            return bool(inside[objid])
        if objtype == int(obj.mjOBJ_SITE):
            return bool(site_inside[objid])
        if objtype == int(obj.mjOBJ_GEOM):
            return bool(geom_inside[objid])
        return False

    for e in range(m.neq):
        t = int(m.eq_type[e])
        if t in (int(mujoco.mjtEq.mjEQ_CONNECT), int(mujoco.mjtEq.mjEQ_WELD)):
            ot = int(m.eq_objtype[e])
            if refers(ot, int(m.eq_obj1id[e])) or refers(ot, int(m.eq_obj2id[e])):
                return False
        elif t != int(mujoco.mjtEq.mjEQ_JOINT):
            return False  # tendon/flex/other equalities: not reasoned about
    trn = mujoco.mjtTrn
    for a in range(m.nu):
        t = int(m.actuator_trntype[a])
        if t in (int(trn.mjTRN_SITE), int(trn.mjTRN_SLIDERCRANK)):
            if any(refers(int(obj.mjOBJ_SITE), int(i)) for i in m.actuator_trnid[a]):
                return False
        elif t == int(trn.mjTRN_BODY):
            if refers(int(obj.mjOBJ_BODY), int(m.actuator_trnid[a, 0])):
                return False
        elif t not in (int(trn.mjTRN_JOINT), int(trn.mjTRN_JOINTINPARENT)):
            return False
    return True


class SimulationUnstableError(RobotError):
    """The simulation diverged. ``time`` (s) and ``quantity`` name what went wrong and when."""

    def __init__(self, time: float, quantity: str, value: float | str) -> None:
        self.time = time
        self.quantity = quantity
        self.value = value
        super().__init__(f"simulation unstable at t = {time:.4f} s: {quantity} = {value}")


@dataclass(frozen=True)
class JointServoGains:
    """Joint stiffness (N m/rad) and damping (N m s/rad) of the internal joint position servo.

    Stiffness: libfranka's default joint impedance. Damping: about critical with the arm's inertia
    plus armature near the default configuration.
    """

    stiffness: tuple[float, ...] = (3000.0, 3000.0, 3000.0, 2500.0, 2500.0, 2000.0, 2000.0)
    damping: tuple[float, ...] = (150.0, 150.0, 110.0, 100.0, 40.0, 40.0, 30.0)

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (7,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"gains.{name} must be 7 positive finite numbers, got {getattr(self, name)!r}")


class SimWorld:
    """Arm + laparoscope + phantom, stepped at 1 kHz with joint position references.

    Physics: timestep 0.5 ms (``SceneConfig.timestep``), 2 substeps per 1 ms tick, implicitfast
    integrator. Scope-incision interaction: a soft weld (2 ms time constant) between the shaft and
    a ball-jointed sliding trocar on the elastic wall (see :mod:`lapwrench.sim.scene`).

    All vectors are in the base (= world) frame, SI units. The wall-on-scope contact force, the
    incision position and the physical RCM error are ground truth from the physics.
    """

    def __init__(
        self,
        scene: Scene | SceneConfig | None = None,
        *,
        gains: JointServoGains | None = None,
        max_contact_force: float = 300.0,
    ) -> None:
        if scene is None or isinstance(scene, SceneConfig):
            scene = build_scene(scene)
        self.scene = scene
        # Own copy: the servo gains are written into the model, and scenes may be shared.
        self.model: mujoco.MjModel = copy.copy(scene.model)
        self.data = mujoco.MjData(self.model)
        self.gains = gains or JointServoGains()
        self.max_contact_force = float(max_contact_force)
        m, d = self.model, self.data
        self.n_substeps = round(CONTROL_DT / m.opt.timestep)
        self._qadr = scene.arm_qpos_adr
        self._vadr = scene.arm_dof_adr
        self._kp = np.asarray(self.gains.stiffness, float)
        self._kv = np.asarray(self.gains.damping, float)
        self._act = np.array([m.actuator(f"servo_{n}").id for n in scene.arm_joint_names])
        m.actuator_gainprm[self._act, 0] = self._kp
        m.actuator_biasprm[self._act, 1] = -self._kp
        m.actuator_biasprm[self._act, 2] = -self._kv
        self._armature = m.dof_armature[self._vadr].copy()
        self._dof_damping = m.dof_damping[self._vadr].copy()
        self._tau_max = TAU_MAX.copy()
        self._tau_free = self._tau_max - 1e-9  # |servo torque| below this: not clipped
        self._vsl = _slice_if_contiguous(self._vadr)  # views when possible
        self._qsl = _slice_if_contiguous(self._qadr)

        self._body_ids: dict[str, int] = {}
        self._body_E = self._body_id(FRAME_E)
        self._body_H = self._body_id(FRAME_H)
        self._body_C = self._body_id(FRAME_C)
        self._body_incision = self._body_id(INCISION_BODY)
        self._body_housing = self._body_id(HOUSING_BODY)
        self._weld = m.equality(TROCAR_WELD).id
        self._ball_qadr = m.joint("trocar_pivot").qposadr[0]
        self._sleeve_qadr = m.joint("trocar_slide").qposadr[0]
        self._trocar_R0 = self.model.body_quat[m.body(TROCAR_BODY).id].copy()
        self._depth0 = float(m.eq_data[self._weld, 2])
        scope = scene.config.scope
        self._depth_min = scope.handle_offset + scope.handle_length / 2.0
        self._depth_max = scope.length
        ph = scene.config.phantom
        self._housing_k = ph.housing_stiffness + ph.wall_stiffness
        self._incision_qadr = np.array([m.joint(n).qposadr[0] for n in INCISION_JOINTS])
        self._housing_qadr = np.array([m.joint(n).qposadr[0] for n in HOUSING_JOINTS])
        self._mocap = [int(m.body_mocapid[m.body(b).id]) for b in INSTRUMENT_BODIES]
        self._port_sites = [m.site(s).id for s in PORT_SITES]
        self._tip_sites = [m.site(s).id for s in INSTRUMENT_TIP_SITES]
        self._cam = m.camera(CAMERA_NAME).id
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._scope_vopt = mujoco.MjvOption()
        self._scope_vopt.geomgroup[1] = 0
        self._warn_idx = np.array(
            [
                int(mujoco.mjtWarning.mjWARN_BADQACC),
                int(mujoco.mjtWarning.mjWARN_BADQVEL),
                int(mujoco.mjtWarning.mjWARN_BADQPOS),
            ]
        )

        # Views of MjData's fixed-size arrays (their memory never moves); the efc_* arrays change
        # size with the active constraints and are fetched every tick.
        self._qpos, self._qvel, self._ctrl = d.qpos, d.qvel, d.ctrl
        self._qacc, self._qfrc_actuator, self._qfrc_damper = d.qacc, d.qfrc_actuator, d.qfrc_damper
        self._xpos, self._xmat, self._xfrc_applied = d.xpos, d.xmat, d.xfrc_applied
        self._site_xpos = d.site_xpos
        self._mocap_pos, self._mocap_quat = d.mocap_pos, d.mocap_quat
        self._mocap_pos_flat, self._mocap_quat_flat = d.mocap_pos.reshape(-1), d.mocap_quat.reshape(-1)
        self._eq_active = d.eq_active
        self._warn_number = d.warning.number
        # Arguments of the tick kernels: per-joint constants (rows _C_*), the tick's work rows (_W_*),
        # index tables.
        self._const = np.zeros((5, 7))
        self._const[_C_KV_OVER_KP] = self._kv / self._kp
        self._const[_C_KV] = self._kv
        self._const[_C_TAU_FREE] = self._tau_free
        self._const[_C_DAMPING] = self._dof_damping
        self._const[_C_ARMATURE] = self._armature
        self._work = np.zeros((5, 7))
        self._q_ref_prev = self._work[_W_Q_REF_PREV]  # views into the work table
        self._tau_J_mean = self._work[_W_TAU_MEAN]
        self._idx = np.array([self._act, self._vadr], dtype=np.int64)
        self._no_dq_ref = np.zeros(7)
        self._tick = self.n_substeps * m.opt.timestep
        self._ids = np.array([self._body_E, self._body_incision, self._weld], dtype=np.int64)
        self._depth_range = np.array([self._depth_min, self._depth_max])
        # The state at the last mj_forward (see the module docstring): its position/velocity stages
        # serve the next tick's first substep while this state is unchanged.
        self._mocap_matters = not _mocap_is_inert(m)
        self._fwd = np.zeros(m.nq + m.nv + 7 * m.nmocap + m.neq)
        self._fwd_valid = False
        # The kernels bound to these argument types (compiled or loaded from numba's cache now):
        # called without numba's per-call dispatch, so every call passes exactly these types.
        self._begin_tick = bind(
            _begin_tick, np.zeros(7), self._no_dq_ref, False, False, self._const, self._work, self._idx,
            self._ctrl, self._qpos, self._qvel, self._mocap_pos_flat, self._mocap_quat_flat, False,
            self._eq_active, self._fwd,
        )  # fmt: skip
        self._substep_torque = bind(
            _substep_torque, self._qfrc_actuator, self._qfrc_damper, self._qvel, self._idx, self._const,
            self._work, False, self.n_substeps, self._tick,
        )  # fmt: skip
        self._end_tick = bind(
            _end_tick, self._warn_number, np.zeros((2, 3), np.int64), self._qpos, self._qvel, self._xpos,
            self._xmat, self._ids, self._depth_range, self.max_contact_force, d.efc_type, d.efc_id,
            d.efc_force, self._mocap_pos_flat, self._mocap_quat_flat, self._eq_active, self._fwd,
        )  # fmt: skip
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Compile the tick's kernels now (or load them from numba's cache), not in the first tick:
        one tick and the per-tick calls, then back to the state :meth:`reset` leaves."""
        try:
            self.set_hand_wrench(np.zeros(6))
            self.set_housing_load(np.zeros(3))
            self.contact_force()
            self.step(self.scene.q0)
        except SimulationUnstableError:
            pass  # e.g. a max_contact_force below the resting force: the kernels are compiled anyway
        finally:
            self.reset()

    def _body_id(self, name: str) -> int:
        """Body id by name, looked up once."""
        b = self._body_ids.get(name)
        if b is None:
            b = self._body_ids[name] = int(self.model.body(name).id)
        return b

    # ------------------------------------------------------------------ lifecycle

    def reset(self, q: np.ndarray | None = None) -> None:
        """Restart at rest in configuration ``q`` (default: the scene's q0), loads cleared.

        The trocar is placed where the shaft crosses the wall plane, so with a ``q`` other than q0
        the wall starts deflected (and pushing) by the shaft's offset from the unloaded incision.
        """
        m, d = self.model, self.data
        self._fwd_valid = False
        mujoco.mj_resetData(m, d)
        q0 = self.scene.q0 if q is None else np.asarray(q, float)
        if q0.shape != (7,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"q must be 7 finite joint values, got {q0!r}")
        d.qpos[self._qadr] = q0
        d.ctrl[self._act] = q0
        self._q_ref_prev[:] = q0
        mujoco.mj_kinematics(m, d)
        p_e, dz = self.shaft_axis()
        rest = self.incision_rest_position()
        if abs(dz[2]) < 1e-3:
            raise ValueError("the shaft must cross the body wall (it is parallel to the wall plane)")
        s = (rest[2] - p_e[2]) / dz[2]
        cross = p_e + s * dz
        d.qpos[self._incision_qadr] = (cross - rest)[:2]
        R_t0 = np.zeros(9)
        mujoco.mju_quat2Mat(R_t0, self._trocar_R0)
        R_rel = R_t0.reshape(3, 3).T @ d.xmat[self._body_E].reshape(3, 3)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, R_rel.ravel())
        d.qpos[self._ball_qadr : self._ball_qadr + 4] = quat
        d.qpos[self._sleeve_qadr] = self._depth0 - s
        mujoco.mj_forward(m, d)
        self._tau_J_mean[:] = self.joint_torque_measured()
        self._warn = np.array([self._warn_idx, self._warn_number[self._warn_idx]], dtype=np.int64)
        self._fwd[:] = np.concatenate([d.qpos, d.qvel, self._mocap_pos_flat, self._mocap_quat_flat, d.eq_active])
        self._fwd_valid = True

    def close(self) -> None:
        """Free the renderers (GL contexts)."""
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()

    def __enter__(self) -> SimWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ stepping

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        """Physics timestep (s)."""
        return float(self.model.opt.timestep)

    def step(self, q_ref: np.ndarray, dq_ref: np.ndarray | None = None) -> None:
        """Advance one 1 ms control tick with the arm servoing to ``q_ref`` (rad).

        Raises :class:`SimulationUnstableError` on a non-finite reference or state, a MuJoCo
        divergence warning, or a shaft-incision contact force above ``max_contact_force``.
        """
        q_ref = np.asarray(q_ref, float)
        if q_ref.shape != (7,):
            raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
        if dq_ref is None:
            dq, use_dq = self._no_dq_ref, False
        else:
            dq, use_dq = np.asarray(dq_ref, float), True
            if dq.shape != (7,):
                if not np.all(np.isfinite(q_ref)):
                    raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
                raise SimulationUnstableError(self.time, "joint velocity reference dq_ref", repr(dq))
        if not q_ref.flags.carray:  # the bound kernel's type: C-contiguous, aligned, writeable
            q_ref = q_ref.copy()
        if not dq.flags.carray:
            dq = dq.copy()
        code = self._begin_tick(
            q_ref, dq, use_dq, self._fwd_valid, self._const, self._work, self._idx, self._ctrl, self._qpos,
            self._qvel, self._mocap_pos_flat, self._mocap_quat_flat, self._mocap_matters, self._eq_active,
            self._fwd,
        )  # fmt: skip
        if code > _OK_FULL:
            if code == _BAD_Q_REF:
                raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
            if code == _BAD_DQ_REF:
                raise SimulationUnstableError(self.time, "joint velocity reference dq_ref", repr(dq))
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        self._fwd_valid = False
        self._substeps(reuse_forward=code == _OK_REUSE)
        mujoco.mj_forward(self.model, self.data)
        self._check()

    def _substeps(self, reuse_forward: bool = False) -> None:
        """Run the tick's physics substeps, keeping the tick mean of the link-side joint torque.

        ``reuse_forward``: the position/velocity stages in ``data`` are those of the current state
        (the last ``mj_forward`` was at it), so the first substep needs ``mj_step2`` only.
        """
        m, d = self.model, self.data
        n = self.n_substeps
        args = (self._qfrc_actuator, self._qfrc_damper, self._qvel, self._idx, self._const, self._work)
        substep_torque, tick = self._substep_torque, self._tick
        for k in range(n):
            if k == 0 and reuse_forward:
                mujoco.mj_step2(m, d)
            else:
                mujoco.mj_step(m, d)  # d.qfrc_* now hold this substep's forces, d.qvel its end velocity
            substep_torque(*args, k == n - 1, n, tick)

    def _check(self) -> None:
        d = self.data
        code = self._end_tick(
            self._warn_number, self._warn, self._qpos, self._qvel, self._xpos, self._xmat, self._ids,
            self._depth_range, float(self.max_contact_force), d.efc_type, d.efc_id, d.efc_force,
            self._mocap_pos_flat, self._mocap_quat_flat, self._eq_active, self._fwd,
        )  # fmt: skip
        if code == _OK_REUSE:
            self._fwd_valid = True
            return
        if code == _BAD_WARNING:
            counts = self._warn_number[self._warn_idx]
            names = ["acceleration (qacc)", "velocity (qvel)", "position (qpos)"]
            bad = [n for n, c, c0 in zip(names, counts, self._warn[1], strict=True) if c != c0]
            self._warn[1] = counts
            raise SimulationUnstableError(self.time, f"MuJoCo state {', '.join(bad)}", "NaN/inf or huge (reset)")
        if code == _BAD_STATE:
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        if code == _BAD_DEPTH:
            # The trocar constraint would hold a shaft that is no longer in it.
            raise SimulationUnstableError(
                self.time, "insertion depth of the incision along the shaft (m)", f"{self.insertion_depth():.4f}"
            )
        f = float(np.linalg.norm(self.contact_force()))
        raise SimulationUnstableError(self.time, "shaft-incision contact force |F| (N)", f"{f:.1f}")

    # ------------------------------------------------------------------ robot state

    @property
    def q(self) -> np.ndarray:
        """Arm joint positions (rad)."""
        return self._qpos[self._qsl].copy()

    @property
    def dq(self) -> np.ndarray:
        """Arm joint velocities (rad/s)."""
        return self._qvel[self._vsl].copy()

    @property
    def q_ref(self) -> np.ndarray:
        """Last joint position reference."""
        return self._q_ref_prev.copy()

    def motor_torque(self) -> np.ndarray:
        """Servo torque commanded by the joint controller (PD + gravity compensation, clipped), N m."""
        return self._qfrc_actuator[self._vsl].copy()

    def joint_torque_measured(self) -> np.ndarray:
        """tau_J: link-side joint torque, as the Franka's joint torque sensors measure it (N m).

        The servo torque minus what the rotor inertia (armature) and joint viscous friction take, so
        that M(q) ddq + c(q, dq) + g(q) = tau_J + tau_ext with Pinocchio's rigid-body model.
        """
        v = self._vsl
        return self._qfrc_actuator[v] + self._qfrc_damper[v] - self._armature * self._qacc[v]

    def joint_torque_tick_mean(self) -> np.ndarray:
        """tau_J averaged over the last 1 ms tick (N m): the torque that moved the arm during it.

        The mean over the substeps of the servo and joint damping torques as the integrator applied
        them (see :func:`_substep_torque`), minus the armature's share, armature x (change of
        velocity over the tick) / tick. After :meth:`reset` it is the instantaneous
        :meth:`joint_torque_measured`.
        """
        return self._tau_J_mean.copy()

    def external_torque(self) -> np.ndarray:
        """tau_ext: ground-truth joint torque from external loads (N m).

        The incision contact, the hand wrench and any joint-limit constraint, all projected to the arm
        joints. A Franka-style estimate is tau_J - (M ddq + c + g) computed with the controller model.
        """
        v = self._vadr
        d = self.data
        xfrc = d.qfrc_smooth[v] - (d.qfrc_passive[v] - d.qfrc_bias[v] + d.qfrc_applied[v] + d.qfrc_actuator[v])
        return d.qfrc_constraint[v] + xfrc

    def frame_pose(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation matrix) of a body frame, e.g. ``lap_E``, ``lap_H``, ``lap_C``."""
        b = self._body_id(body)
        return self._xpos[b].copy(), self._xmat[b].reshape(3, 3).copy()

    def shaft_axis(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_E, d_z): flange position and unit shaft direction (+z of lap_E)."""
        b = self._body_E
        return self._xpos[b].copy(), self._xmat[b, 2::3].copy()

    # ------------------------------------------------------------------ phantom state

    def contact_force(self) -> np.ndarray:
        """Force (N, base frame) exerted by the incision (trocar in the wall) on the laparoscope shaft.

        The translational part of the trocar weld's constraint force, acting at the incision point.
        """
        # The weld's rows 0-2 constrain (sleeve anchor - shaft anchor) in world axes: J^T f applies -f
        # to the shaft. Zero when the weld has no rows (inactive).
        d = self.data
        f = np.empty(3)
        _weld_force(d.efc_type, d.efc_id, d.efc_force, self._weld, f)
        return f

    def incision_position(self) -> np.ndarray:
        """Current incision point (ring centre), base frame."""
        return self._xpos[self._body_incision].copy()

    def incision_rest_position(self) -> np.ndarray:
        """Where the incision would sit with no shaft load (moves with the housing)."""
        return self._xpos[self._body_housing].copy()

    def incision_deflection(self) -> np.ndarray:
        """Wall deflection at the incision (incision - rest), base frame (m)."""
        return self.incision_position() - self.incision_rest_position()

    def housing_displacement(self) -> np.ndarray:
        """Lateral displacement (x, y, 0) of the phantom housing from its initial place (m)."""
        return np.array([*self._qpos[self._housing_qadr], 0.0])

    def rcm_error(self) -> float:
        """Physical RCM error (m): distance from the incision point to the shaft axis line."""
        p, dz = self.shaft_axis()
        r = self.incision_position() - p
        return float(np.linalg.norm(r - (r @ dz) * dz))

    def insertion_depth(self) -> float:
        """Distance (m) from lap_E to the incision along the shaft (lambda * L)."""
        p, dz = self.shaft_axis()
        return float((self.incision_position() - p) @ dz)

    # ------------------------------------------------------------------ loads and props

    def set_hand_wrench(self, wrench: np.ndarray) -> None:
        """Apply the surgeon's hand wrench [f, tau] (N, N m; base frame, about lap_H) until changed."""
        w = np.asarray(wrench, float)
        if w.shape != (6,) or not _all_finite(w):
            raise ValueError(f"hand wrench must be 6 finite numbers, got {wrench!r}")
        # lap_H is massless, so its xfrc_applied acts at the lap_H origin.
        self._xfrc_applied[self._body_H] = w

    def hand_wrench(self) -> np.ndarray:
        """The hand wrench currently applied at lap_H."""
        return self._xfrc_applied[self._body_H].copy()

    def set_housing_load(self, force: np.ndarray) -> None:
        """Sustained force (N, base frame) on the phantom housing (only x, y move it)."""
        f = np.asarray(force, float)
        if f.shape != (3,) or not _all_finite(f):
            raise ValueError(f"housing load must be 3 finite numbers, got {force!r}")
        self._xfrc_applied[self._body_housing, :3] = f

    def housing_load_for_shift(self, shift: np.ndarray) -> np.ndarray:
        """Housing load (N) that shifts the phantom by ``shift`` (m, x/y) while the scope holds still.

        With the shaft held, the housing spring and the wall spring act in parallel.
        """
        sh = np.asarray(shift, float)
        return np.array([sh[0], sh[1], 0.0]) * self._housing_k

    @property
    def n_instruments(self) -> int:
        """Number of instruments in the scene (each with its own port)."""
        return len(self._mocap)

    def port_position(self, index: int) -> np.ndarray:
        """World position of instrument port ``index`` (0 left, 1 right); moves with the housing."""
        return self._site_xpos[self._port_sites[index]].copy()

    def set_instrument_pose(self, index: int, pos: np.ndarray, quat: np.ndarray) -> None:
        """Raw mocap pose of instrument ``index`` (origin at the jaw tip, quat wxyz)."""
        mid = self._mocap[index]
        self._mocap_pos[mid] = pos
        self._mocap_quat[mid] = quat

    def set_instrument_tip(self, index: int, tip: np.ndarray, roll: float = 0.0) -> None:
        """Put instrument ``index``'s jaw tip at ``tip`` with its shaft through its port."""
        pos, quat = instrument_pose_through_port(self.port_position(index), np.asarray(tip, float), roll)
        self.set_instrument_pose(index, pos, quat)

    def instrument_tip(self, index: int) -> np.ndarray:
        """Jaw tip position of instrument ``index`` (as last set; updated by the next step)."""
        return self._mocap_pos[self._mocap[index]].copy()

    def project_to_image(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (u, v) of world points in the laparoscope image and their depth z_C."""
        p, R = self.frame_pose(FRAME_C)
        pc = (np.asarray(points, float) - p) @ R
        return self.scene.config.camera.project(pc), pc[..., 2]

    # ------------------------------------------------------------------ rendering

    def render(self, camera: str = CAMERA_NAME, width: int | None = None, height: int | None = None) -> np.ndarray:
        """RGB uint8 image (height, width, 3); default: the 640 x 480 laparoscope view."""
        cam = self.scene.config.camera
        w = width or cam.width
        h = height or cam.height
        key = (w, h)
        r = self._renderers.get(key)
        if r is None:
            r = mujoco.Renderer(self.model, height=h, width=w)
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
            self._renderers[key] = r
        # The arm (geom group 1) is never in the laparoscope's view: skip drawing it there.
        r.update_scene(self.data, camera=camera, scene_option=self._scope_vopt if camera == CAMERA_NAME else None)
        return r.render()
