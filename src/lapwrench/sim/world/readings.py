"""What :class:`~lapwrench.sim.world.SimWorld` reads from the physics: the arm's joint state and torques,
frame poses, and the phantom's ground truth (trocar contact force, incision, RCM error, insertion depth).

A mixin: the world builds the views of ``MjData`` and the ids it reads (listed below) at construction.
All vectors are in the base (= world) frame, SI units.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from lapwrench.jit import kernel
from lapwrench.rcm.geometry import axis_rcm_error_and_depth
from lapwrench.robot.description import FRAME_C
from lapwrench.robot.model import scope_axis
from lapwrench.sim.scene.build import Scene


@kernel
def axis_offset_of_body(xpos: np.ndarray, xmat: np.ndarray, body: int, point: np.ndarray,
                        length: float) -> tuple[float, float]:
    """The controller's eq (27) |e_R| and tip depth (:func:`~lapwrench.rcm.geometry.axis_rcm_error_and_depth`)
    for the scope axis of MuJoCo's pose of ``body`` (``xpos``, ``xmat``: ``MjData``'s rows) and ``point``:
    the two kernels in one call from Python."""
    d_z, P = scope_axis(xmat[body].reshape((3, 3)))
    return axis_rcm_error_and_depth(xpos[body], d_z, P, point, length)


class WorldReadings:
    """Robot state, frame poses and phantom ground truth of a :class:`~lapwrench.sim.world.SimWorld`."""

    scene: Scene
    model: mujoco.MjModel
    data: mujoco.MjData
    _body_ids: dict[str, int]
    _body_E: int
    _body_incision: int
    _body_housing: int
    _weld: int
    n_joints: int
    _qadr: np.ndarray
    _vadr: np.ndarray
    _qsl: slice | np.ndarray
    _vsl: slice | np.ndarray
    _housing_qadr: np.ndarray
    _armature: np.ndarray
    _qpos: np.ndarray
    _qvel: np.ndarray
    _qacc: np.ndarray
    _qfrc_actuator: np.ndarray
    _qfrc_damper: np.ndarray
    _xpos: np.ndarray
    _xmat: np.ndarray
    _q_ref_prev: np.ndarray
    _tau_J_mean: np.ndarray
    _scope_length: float
    # kernels bound at construction (:mod:`.core`): _weld_force, axis_offset_of_body
    _weld_force: Callable[..., None]
    _axis_offset: Callable[..., tuple[float, float]]

    def _body_id(self, name: str) -> int:
        """Body id by name, looked up once."""
        b = self._body_ids.get(name)
        if b is None:
            b = self._body_ids[name] = int(self.model.body(name).id)
        return b

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
        them (see :func:`~lapwrench.sim.world.kernels._substep_torque`), minus the armature's share,
        armature x (change of velocity over the tick) / tick. After :meth:`reset` it is the
        instantaneous :meth:`joint_torque_measured`.
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
        self._weld_force(d.efc_type, d.efc_id, d.efc_force, self._weld, f)
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

    def axis_offset(self, point: np.ndarray) -> tuple[float, float]:
        """(distance (m) from ``point`` to the shaft axis line, depth (m) of the scope tip beyond
        ``point`` along the shaft) for the simulated scope's pose.

        The controller's eq (27) |e_R| and tip depth (:func:`~lapwrench.rcm.geometry.axis_rcm_error_and_depth`,
        the one copy of those formulas) with MuJoCo's lap_E pose and a ground-truth point in
        place of the model's p_E and the controller's p_R.
        """
        point = np.ascontiguousarray(point, dtype=np.float64)  # the bound kernel's type
        if point.shape != (3,):
            raise ValueError(f"point must be 3 numbers, got shape {point.shape}")
        return self._axis_offset(self._xpos, self._xmat, self._body_E, point, self._scope_length)

    def rcm_error(self) -> float:
        """Physical RCM error (m): distance from the current incision point (the trocar, which
        sits on the shaft) to the shaft axis line (:meth:`axis_offset`). Near zero by construction;
        :meth:`~lapwrench.sim.loop.ClosedLoop.physical_rcm_error` measures from the *unloaded*
        incision instead."""
        return self.axis_offset(self.incision_position())[0]

    def insertion_depth(self) -> float:
        """Distance (m) from lap_E to the incision along the shaft (lambda * L)."""
        p, dz = self.shaft_axis()
        return float((self.incision_position() - p) @ dz)

    def project_to_image(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (u, v) of world points in the laparoscope image and their depth z_C."""
        p, R = self.frame_pose(FRAME_C)
        pc = (np.asarray(points, float) - p) @ R
        return self.scene.config.camera.project(pc), pc[..., 2]
