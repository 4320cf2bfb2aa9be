"""Building :class:`SimWorld`: arm + laparoscope + phantom in MuJoCo, with the servo gains written into its
own copy of the model, the views and tables the tick kernels run on, and the reset to rest.

The class is assembled from mixins, one job each: the tick (:mod:`.stepping`), the readings
(:mod:`.readings`), the loads and instruments (:mod:`.loads`) and rendering (:mod:`.rendering`). This
module owns the state they share: everything is created here, in :meth:`SimWorld.__init__`.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from lapwrench.jit import bind
from lapwrench.robot.description import FRAME_C, FRAME_E, FRAME_H
from lapwrench.robot.limits import joint_torque_limits
from lapwrench.sim.offscreen import scope_view_option
from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import SceneConfig
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
from lapwrench.sim.world.errors import SimulationUnstableError
from lapwrench.sim.world.gains import JointServoGains
from lapwrench.sim.world.kernels import (
    _C_ARMATURE,
    _C_DAMPING,
    _C_KV,
    _C_KV_OVER_KP,
    _C_TAU_FREE,
    _W_Q_REF_PREV,
    _W_TAU_MEAN,
    CONTROL_DT,
    _begin_tick,
    _end_tick,
    _substep_torque,
    _weld_force,
)
from lapwrench.sim.world.loads import WorldLoads
from lapwrench.sim.world.model_facts import _slice_if_contiguous, contacts_impossible, mocap_is_inert
from lapwrench.sim.world.readings import axis_offset_of_body
from lapwrench.sim.world.rendering import WorldRendering
from lapwrench.sim.world.stepping import WorldStepping


class SimWorld(WorldStepping, WorldLoads, WorldRendering):
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
        self.gains = gains or JointServoGains.for_robot(scene.config.kind)
        self.max_contact_force = float(max_contact_force)
        m, d = self.model, self.data
        self.n_substeps = round(CONTROL_DT / m.opt.timestep)
        self._qadr = scene.arm_qpos_adr
        self.n_joints = int(self._qadr.shape[0])
        if len(self.gains.stiffness) != self.n_joints:
            raise ValueError(f"gains: {len(self.gains.stiffness)} values, the {scene.config.kind} arm has "
                             f"{self.n_joints} joints")
        self._vadr = scene.arm_dof_adr
        self._kp = np.asarray(self.gains.stiffness, float)
        self._kv = np.asarray(self.gains.damping, float)
        self._act = np.array([m.actuator(f"servo_{n}").id for n in scene.arm_joint_names])
        m.actuator_gainprm[self._act, 0] = self._kp
        m.actuator_biasprm[self._act, 1] = -self._kp
        m.actuator_biasprm[self._act, 2] = -self._kv
        if contacts_impossible(m):  # no geoms that can touch: skip collision detection (same results)
            m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self._opt = m.opt  # the substeps switch the sensors off (stepping)
        self._armature = m.dof_armature[self._vadr].copy()
        self._dof_damping = m.dof_damping[self._vadr].copy()
        self._tau_max = joint_torque_limits(scene.config.kind)
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
        self._scope_vopt = scope_view_option()
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
        self._const = np.zeros((5, self.n_joints))
        self._const[_C_KV_OVER_KP] = self._kv / self._kp
        self._const[_C_KV] = self._kv
        self._const[_C_TAU_FREE] = self._tau_free
        self._const[_C_DAMPING] = self._dof_damping
        self._const[_C_ARMATURE] = self._armature
        self._work = np.zeros((5, self.n_joints))
        self._q_ref_prev = self._work[_W_Q_REF_PREV]  # views into the work table
        self._tau_J_mean = self._work[_W_TAU_MEAN]
        self._idx = np.array([self._act, self._vadr], dtype=np.int64)
        self._no_dq_ref = np.zeros(self.n_joints)
        self._tick = self.n_substeps * m.opt.timestep
        self._ids = np.array([self._body_E, self._body_incision, self._weld], dtype=np.int64)
        self._depth_range = np.array([self._depth_min, self._depth_max])
        # The state at the last mj_forward (see the module docstring): its position/velocity stages
        # serve the next tick's first substep while this state is unchanged.
        self._mocap_matters = not mocap_is_inert(m)
        self._fwd = np.zeros(m.nq + m.nv + (3 + 4) * m.nmocap + m.neq)  # mocap: position, quaternion
        self._fwd_valid = False
        # The kernels bound to these argument types (compiled or loaded from numba's cache now):
        # called without numba's per-call dispatch, so every call passes exactly these types.
        self._begin_tick = bind(
            _begin_tick, np.zeros(self.n_joints), self._no_dq_ref, False, False, self._const, self._work, self._idx,
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
        # The readings' kernels, bound as well: the scenarios' records read them every tick.
        z3 = np.zeros(3)
        self._weld_force = bind(_weld_force, d.efc_type, d.efc_id, d.efc_force, self._weld, z3)
        self._scope_length = float(scene.config.scope.length)
        self._axis_offset = bind(axis_offset_of_body, self._xpos, self._xmat, self._body_E, z3, self._scope_length)
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Compile the tick's kernels now (or load them from numba's cache), not in the first tick:
        one tick and the per-tick calls, then back to the state :meth:`reset` leaves."""
        try:
            self.set_hand_wrench()
            self.set_housing_load(np.zeros(3))
            self.contact_force()
            self.step(self.scene.q0)
        except SimulationUnstableError:
            pass  # e.g. a max_contact_force below the resting force: the kernels are compiled anyway
        finally:
            self.reset()

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
        if q0.shape != (self.n_joints,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"q must be {self.n_joints} finite joint values, got {q0!r}")
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

    def __enter__(self) -> SimWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
