"""Joint configurations that put the scope at a given pivot about the incision (MuJoCo kinematics).

Used to pose the arm for the synthetic dataset (:mod:`lapwrench.sim.dataset`): damped least squares
on the flange pose, from the scene's default configuration, inside the joint limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np


def _rotvec_matrix(rv: Sequence[float] | np.ndarray) -> np.ndarray:
    R, _ = cv2.Rodrigues(np.asarray(rv, np.float64).reshape(3, 1))
    return R


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class ScopePoser:
    """Joint configurations that pivot the scope about the incision (kinematics only).

    ``configuration(tilt_x, tilt_y, roll, insertion)`` rotates the default scope orientation by
    ``(tilt_x, tilt_y)`` (rad, about world x/y) through the incision point, rolls it by ``roll``
    about its axis and moves it ``insertion`` metres deeper; the joint configuration is solved by
    damped least squares on the flange pose from q0. Returns ``None`` when it does not converge
    within the joint limits.
    """

    def __init__(self, world: Any) -> None:
        import mujoco

        self._mj = mujoco
        self.model = world.model
        self.data = mujoco.MjData(self.model)
        self.q0 = np.asarray(world.scene.q0, float)
        self.qadr = world.scene.arm_qpos_adr
        self.vadr = world.scene.arm_dof_adr
        jids = [self.model.joint(n).id for n in world.scene.arm_joint_names]
        self.lower = self.model.jnt_range[jids, 0] + 0.02
        self.upper = self.model.jnt_range[jids, 1] - 0.02
        from lapwrench.robot.description import FRAME_E

        self.body = self.model.body(FRAME_E).id
        p0, R0 = self._fk(self.q0)
        self.R0 = R0
        self.incision = np.asarray(world.scene.incision_position, float)
        self.depth0 = float((self.incision - p0) @ R0[:, 2])

    def _fk(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.data.qpos[self.qadr] = q
        self._mj.mj_kinematics(self.model, self.data)
        self._mj.mj_comPos(self.model, self.data)  # cdof, needed by mj_jacBody
        return self.data.xpos[self.body].copy(), self.data.xmat[self.body].reshape(3, 3).copy()

    def target(self, tilt_x: float, tilt_y: float, roll: float, insertion: float) -> tuple[np.ndarray, np.ndarray]:
        R = _rotvec_matrix([tilt_x, tilt_y, 0.0]) @ self.R0 @ _rot_z(roll)
        p = self.incision - (self.depth0 + insertion) * R[:, 2]
        return p, R

    def configuration(
        self, tilt_x: float, tilt_y: float, roll: float, insertion: float, iters: int = 100
    ) -> np.ndarray | None:
        mj = self._mj
        p_t, R_t = self.target(tilt_x, tilt_y, roll, insertion)
        q = self.q0.copy()
        jacp = np.zeros((3, self.model.nv))
        jacr = np.zeros((3, self.model.nv))
        for _ in range(iters):
            p, R = self._fk(q)
            e_p = p_t - p
            e_r = 0.5 * sum(np.cross(R[:, k], R_t[:, k]) for k in range(3))
            if np.linalg.norm(e_p) < 1e-5 and np.linalg.norm(e_r) < 1e-4:
                return q
            mj.mj_jacBody(self.model, self.data, jacp, jacr, self.body)
            J = np.vstack([jacp[:, self.vadr], jacr[:, self.vadr]])
            e = np.r_[e_p, e_r]
            dq = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(6), e)
            q = np.clip(q + dq, self.lower, self.upper)
        return None
