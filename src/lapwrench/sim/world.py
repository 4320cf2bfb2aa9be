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
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from lapwrench.robot.description import FRAME_C, FRAME_E, FRAME_H
from lapwrench.robot.interface import RobotError
from lapwrench.sim.scene import (
    CAMERA_NAME,
    HOUSING_BODY,
    HOUSING_JOINTS,
    INCISION_BODY,
    INCISION_JOINTS,
    INSTRUMENT_BODIES,
    INSTRUMENT_TIP_SITES,
    PORT_SITES,
    TAU_MAX,
    TROCAR_BODY,
    TROCAR_WELD,
    Scene,
    SceneConfig,
    build_scene,
    instrument_pose_through_port,
)

CONTROL_DT = 0.001


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
        m = self.model
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
        v0 = int(self._vadr[0])
        contiguous = np.array_equal(self._vadr, np.arange(v0, v0 + 7))
        self._vsl: slice | np.ndarray = slice(v0, v0 + 7) if contiguous else self._vadr  # views when possible

        self._body_E = m.body(FRAME_E).id
        self._body_H = m.body(FRAME_H).id
        self._body_C = m.body(FRAME_C).id
        self._body_incision = m.body(INCISION_BODY).id
        self._body_housing = m.body(HOUSING_BODY).id
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
        self._q_ref_prev: np.ndarray | None = None
        self._warn_idx = [
            int(mujoco.mjtWarning.mjWARN_BADQACC),
            int(mujoco.mjtWarning.mjWARN_BADQVEL),
            int(mujoco.mjtWarning.mjWARN_BADQPOS),
        ]
        self.reset()

    # ------------------------------------------------------------------ lifecycle

    def reset(self, q: np.ndarray | None = None) -> None:
        """Restart at rest in configuration ``q`` (default: the scene's q0), loads cleared.

        The trocar is placed where the shaft crosses the wall plane, so with a ``q`` other than q0
        the wall starts deflected (and pushing) by the shaft's offset from the unloaded incision.
        """
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        q0 = self.scene.q0 if q is None else np.asarray(q, float)
        if q0.shape != (7,) or not np.all(np.isfinite(q0)):
            raise ValueError(f"q must be 7 finite joint values, got {q0!r}")
        d.qpos[self._qadr] = q0
        d.ctrl[self._act] = q0
        self._q_ref_prev = q0.copy()
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
        self._tau_J_mean = self.joint_torque_measured()
        self._warn_counts = [self.data.warning[i].number for i in self._warn_idx]

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
        if q_ref.shape != (7,) or not np.all(np.isfinite(q_ref)):
            raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
        if dq_ref is None:
            dq_ref = (q_ref - self._q_ref_prev) / CONTROL_DT
        else:
            dq_ref = np.asarray(dq_ref, float)
            if dq_ref.shape != (7,) or not np.all(np.isfinite(dq_ref)):
                raise SimulationUnstableError(self.time, "joint velocity reference dq_ref", repr(dq_ref))
        self._q_ref_prev = q_ref.copy()
        # force = kp*ctrl - kp*q - kv*dq  with ctrl = q_ref + kv/kp dq_ref
        self.data.ctrl[self._act] = q_ref + (self._kv / self._kp) * dq_ref
        d = self.data
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        self._substeps()
        mujoco.mj_forward(self.model, d)
        self._check()

    def _substeps(self) -> None:
        """Run the tick's physics substeps, keeping the tick mean of the link-side joint torque."""
        m, d, v = self.model, self.data, self._vsl
        total = np.zeros(7)
        v_tick = d.qvel[v].copy()
        for _ in range(self.n_substeps):
            v_start = d.qvel[v].copy()
            mujoco.mj_step(m, d)  # d.qfrc_* now hold this substep's forces, d.qvel its end velocity
            total += self._substep_joint_torque(d.qvel[v] - v_start)
        tick = self.n_substeps * m.opt.timestep
        self._tau_J_mean = total / self.n_substeps - self._armature * (d.qvel[v] - v_tick) / tick

    def _substep_joint_torque(self, dv: np.ndarray) -> np.ndarray:
        """Servo plus joint damping torque as ``implicitfast`` applied them over the substep just taken.

        Their velocity terms act at the end-of-substep velocity: -(kv + b) dv on top of the values at
        its start, except on a servo clipped at tau_max (then its torque does not depend on velocity).
        """
        d, v = self.data, self._vsl
        tau = d.qfrc_actuator[v]
        kv = self._kv * (np.abs(tau) < self._tau_free)
        return tau + d.qfrc_damper[v] - (kv + self._dof_damping) * dv

    def _check(self) -> None:
        d = self.data
        counts = [d.warning[i].number for i in self._warn_idx]
        if counts != self._warn_counts:
            names = ["acceleration (qacc)", "velocity (qvel)", "position (qpos)"]
            bad = [n for n, c, c0 in zip(names, counts, self._warn_counts, strict=True) if c != c0]
            self._warn_counts = counts
            raise SimulationUnstableError(self.time, f"MuJoCo state {', '.join(bad)}", "NaN/inf or huge (reset)")
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        depth = self.insertion_depth()
        if not (self._depth_min < depth < self._depth_max):
            # The trocar constraint would hold a shaft that is no longer in it.
            raise SimulationUnstableError(
                self.time, "insertion depth of the incision along the shaft (m)", f"{depth:.4f}"
            )
        f = float(np.linalg.norm(self.contact_force()))
        if not math.isfinite(f) or f > self.max_contact_force:
            raise SimulationUnstableError(self.time, "shaft-incision contact force |F| (N)", f"{f:.1f}")

    # ------------------------------------------------------------------ robot state

    @property
    def q(self) -> np.ndarray:
        """Arm joint positions (rad)."""
        return self.data.qpos[self._qadr].copy()

    @property
    def dq(self) -> np.ndarray:
        """Arm joint velocities (rad/s)."""
        return self.data.qvel[self._vadr].copy()

    @property
    def q_ref(self) -> np.ndarray:
        """Last joint position reference."""
        return self._q_ref_prev.copy()

    def motor_torque(self) -> np.ndarray:
        """Servo torque commanded by the joint controller (PD + gravity compensation, clipped), N m."""
        return self.data.qfrc_actuator[self._vadr].copy()

    def joint_torque_measured(self) -> np.ndarray:
        """tau_J: link-side joint torque, as the Franka's joint torque sensors measure it (N m).

        The servo torque minus what the rotor inertia (armature) and joint viscous friction take, so
        that M(q) ddq + c(q, dq) + g(q) = tau_J + tau_ext with Pinocchio's rigid-body model.
        """
        v = self._vadr
        d = self.data
        return d.qfrc_actuator[v] + d.qfrc_damper[v] - self._armature * d.qacc[v]

    def joint_torque_tick_mean(self) -> np.ndarray:
        """tau_J averaged over the last 1 ms tick (N m): the torque that moved the arm during it.

        The mean over the substeps of the servo and joint damping torques as the integrator applied
        them (see :meth:`_substep_joint_torque`), minus the armature's share, armature x (change of
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
        b = self.model.body(body).id
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    def shaft_axis(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_E, d_z): flange position and unit shaft direction (+z of lap_E)."""
        b = self._body_E
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3)[:, 2].copy()

    # ------------------------------------------------------------------ phantom state

    def contact_force(self) -> np.ndarray:
        """Force (N, base frame) exerted by the incision (trocar in the wall) on the laparoscope shaft.

        The translational part of the trocar weld's constraint force, acting at the incision point.
        """
        d = self.data
        rows = np.flatnonzero(
            (d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id[: d.nefc] == self._weld)
        )
        if rows.size < 3:
            return np.zeros(3)
        # Rows 0-2 constrain (sleeve anchor - shaft anchor) in world axes: J^T f applies -f to the shaft.
        return -d.efc_force[rows[:3]]

    def incision_position(self) -> np.ndarray:
        """Current incision point (ring centre), base frame."""
        return self.data.xpos[self._body_incision].copy()

    def incision_rest_position(self) -> np.ndarray:
        """Where the incision would sit with no shaft load (moves with the housing)."""
        return self.data.xpos[self._body_housing].copy()

    def incision_deflection(self) -> np.ndarray:
        """Wall deflection at the incision (incision - rest), base frame (m)."""
        return self.incision_position() - self.incision_rest_position()

    def housing_displacement(self) -> np.ndarray:
        """Lateral displacement (x, y, 0) of the phantom housing from its initial place (m)."""
        return np.array([*self.data.qpos[self._housing_qadr], 0.0])

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
        if w.shape != (6,) or not np.all(np.isfinite(w)):
            raise ValueError(f"hand wrench must be 6 finite numbers, got {wrench!r}")
        # lap_H is massless, so its xfrc_applied acts at the lap_H origin.
        self.data.xfrc_applied[self._body_H] = w

    def hand_wrench(self) -> np.ndarray:
        """The hand wrench currently applied at lap_H."""
        return self.data.xfrc_applied[self._body_H].copy()

    def set_housing_load(self, force: np.ndarray) -> None:
        """Sustained force (N, base frame) on the phantom housing (only x, y move it)."""
        f = np.asarray(force, float)
        if f.shape != (3,) or not np.all(np.isfinite(f)):
            raise ValueError(f"housing load must be 3 finite numbers, got {force!r}")
        self.data.xfrc_applied[self._body_housing, :3] = f

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
        return self.data.site_xpos[self._port_sites[index]].copy()

    def set_instrument_pose(self, index: int, pos: np.ndarray, quat: np.ndarray) -> None:
        """Raw mocap pose of instrument ``index`` (origin at the jaw tip, quat wxyz)."""
        mid = self._mocap[index]
        self.data.mocap_pos[mid] = pos
        self.data.mocap_quat[mid] = quat

    def set_instrument_tip(self, index: int, tip: np.ndarray, roll: float = 0.0) -> None:
        """Put instrument ``index``'s jaw tip at ``tip`` with its shaft through its port."""
        pos, quat = instrument_pose_through_port(self.port_position(index), np.asarray(tip, float), roll)
        self.set_instrument_pose(index, pos, quat)

    def instrument_tip(self, index: int) -> np.ndarray:
        """Jaw tip position of instrument ``index`` (as last set; updated by the next step)."""
        return self.data.mocap_pos[self._mocap[index]].copy()

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
