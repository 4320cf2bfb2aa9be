"""The two laparoscopic instruments: mocap bodies (black shafts with metallic jaws) posed by the
caller through their own ports in the wall, and the pose of an instrument through its port.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from lapwrench.sim.scene.config import PhantomConfig
from lapwrench.sim.scene.names import INSTRUMENT_BODIES, INSTRUMENT_TIP_SITES


def add_instruments(spec: mujoco.MjSpec, incision: np.ndarray, ph: PhantomConfig) -> None:
    """Two mocap instruments; frame origin at the jaw tip, +z pointing distally along the shaft."""
    vis = {"contype": 0, "conaffinity": 0, "group": 2, "density": 0.0}
    for body, tip_site, (px, py) in zip(INSTRUMENT_BODIES, INSTRUMENT_TIP_SITES, ph.port_offsets, strict=True):
        port = incision + np.array([px, py, 0.0])
        tip = incision + np.array([0.3 * px - 0.01, 0.22 * py, -0.125])
        pos, quat = instrument_pose_through_port(port, tip)
        b = spec.worldbody.add_body(name=body, mocap=True, pos=list(pos), quat=list(quat))
        b.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0, 0, -0.42, 0, 0, -0.026],
            size=[0.0026, 0, 0],
            material="black",
            **vis,
        )
        b.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.0029, 0.004, 0], pos=[0, 0, -0.022], material="metal", **vis
        )
        for s in (-1.0, 1.0):
            ang = s * 0.22
            b.add_geom(
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[0.0011, 0.0016, 0.0085],
                pos=[0, s * 0.0019 + s * 0.0085 * math.sin(ang), -0.0095],
                quat=[math.cos(-ang / 2), math.sin(-ang / 2), 0, 0],
                material="metal",
                **vis,
            )
        b.add_site(name=tip_site, pos=[0, 0, 0], size=[0.002, 0, 0], group=4)
        b.add_site(name=f"{body}_jaw", pos=[0, 0, -0.02], size=[0.002, 0, 0], group=4)


def instrument_pose_through_port(port: np.ndarray, tip: np.ndarray, roll: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Mocap pose (pos, quat wxyz) of an instrument whose shaft passes through ``port`` to ``tip``.

    The instrument frame has its origin at the jaw tip and +z along the shaft toward the tip; ``roll``
    rotates it about its shaft.
    """
    # Called every tick while an instrument moves: scalar arithmetic, the same operations (and
    # bits) as np.cross / np.linalg.norm on the 3-vectors, without their per-call overhead.
    tip = np.asarray(tip, float)
    z = tip - np.asarray(port, float)
    nz = math.sqrt(z.dot(z))
    if nz < 1e-6:
        raise ValueError("instrument tip coincides with its port")
    z0, z1, z2 = (z / nz).tolist()
    if abs(z2) < 0.9:  # x = ref x z, ref = (0, 0, 1)
        x0, x1, x2 = 0.0 * z2 - 1.0 * z1, 1.0 * z0 - 0.0 * z2, 0.0 * z1 - 0.0 * z0
    else:  # ref = (1, 0, 0)
        x0, x1, x2 = 0.0 * z2 - 0.0 * z1, 0.0 * z0 - 1.0 * z2, 1.0 * z1 - 0.0 * z0
    nx = math.sqrt(np.dot((x0, x1, x2), (x0, x1, x2)))
    x0, x1, x2 = x0 / nx, x1 / nx, x2 / nx
    y0, y1, y2 = z1 * x2 - z2 * x1, z2 * x0 - z0 * x2, z0 * x1 - z1 * x0  # z x x
    c, s = math.cos(roll), math.sin(roll)
    x0, x1, x2, y0, y1, y2 = (
        c * x0 + s * y0, c * x1 + s * y1, c * x2 + s * y2, -s * x0 + c * y0, -s * x1 + c * y1, -s * x2 + c * y2,
    )  # fmt: skip
    R = np.array([x0, y0, z0, x1, y1, z1, x2, y2, z2])  # columns x, y, z (row-major)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R)
    return tip.copy(), quat
