"""The abdominal phantom on its table: housing, body wall, ports, tissue floor, organ, needle, gauze.

The phantom (body ``housing``) is a box shell on two horizontal spring-damper slides, so a
sustained lateral load displaces it (Fig. 5 disturbance). It carries a body wall (visual mesh with
holes at the incision and the two instrument ports), a textured tissue floor and organ, a suture
needle and two gauze pads. The incision and its trocar are added to the housing by
:mod:`lapwrench.sim.scene.trocar`.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from lapwrench.sim.scene.config import PhantomConfig
from lapwrench.sim.scene.names import (
    GAUZE_BODIES,
    HOUSING_BODY,
    HOUSING_JOINTS,
    NEEDLE_BODY,
    ORGAN_BODY,
    PORT_SITES,
    UNSEEN_BY_SCOPE_GROUP,
)


def _wall_mesh(
    size_x: float, size_y: float, thickness: float, holes: list[tuple[float, float, float]], cell: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Slab (top + bottom faces) on a grid, without the cells inside the circular ``holes``."""
    nx, ny = round(size_x / cell), round(size_y / cell)
    xs = np.linspace(-size_x / 2, size_x / 2, nx + 1)
    ys = np.linspace(-size_y / 2, size_y / 2, ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    top = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, thickness / 2)], axis=1)
    bot = top.copy()
    bot[:, 2] = -thickness / 2
    verts = np.concatenate([top, bot])
    nv = top.shape[0]
    faces = []
    for i in range(nx):
        cx = 0.5 * (xs[i] + xs[i + 1])
        for j in range(ny):
            cy = 0.5 * (ys[j] + ys[j + 1])
            if any((cx - hx) ** 2 + (cy - hy) ** 2 < hr**2 for hx, hy, hr in holes):
                continue
            a, b = i * (ny + 1) + j, (i + 1) * (ny + 1) + j
            c, d = b + 1, a + 1
            faces += [(a, b, c), (a, c, d), (nv + a, nv + c, nv + b), (nv + a, nv + d, nv + c)]
    return verts, np.array(faces, dtype=np.int32)


def add_phantom(spec: mujoco.MjSpec, ph: PhantomConfig, incision: np.ndarray) -> mujoco.MjsBody:
    """Floor, table and the phantom centred on the rest ``incision``; returns the housing body."""
    vis = {"contype": 0, "conaffinity": 0, "group": 2, "density": 0.0}
    world = spec.worldbody
    sx, sy, depth, wt = ph.size_x, ph.size_y, ph.depth, ph.wall_thickness

    room = {**vis, "group": UNSEEN_BY_SCOPE_GROUP}  # outside the closed housing: never in the laparoscope's view
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.05], material="floor", **room)
    # Table under the phantom.
    table_top = incision[2] - depth - 0.01
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.3, 0.3, table_top / 2],
        pos=[incision[0], incision[1], table_top / 2],
        rgba=[0.6, 0.6, 0.62, 1],
        **room,
    )

    housing = world.add_body(name=HOUSING_BODY, pos=list(incision))
    housing.explicitinertial = True
    housing.mass = ph.housing_mass
    housing.ipos = [0, 0, -depth / 2]
    ixx = ph.housing_mass * (sy**2 + depth**2) / 12
    iyy = ph.housing_mass * (sx**2 + depth**2) / 12
    izz = ph.housing_mass * (sx**2 + sy**2) / 12
    housing.inertia = [ixx, iyy, izz]
    for name, axis in zip(HOUSING_JOINTS, ([1, 0, 0], [0, 1, 0]), strict=True):
        housing.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=axis,
            stiffness=ph.housing_stiffness,
            damping=ph.housing_damping,
            armature=0.0,
        )
    # Box shell: floor plate and four side walls (inner cavity sx x sy x depth).
    t = 0.008
    housing.add_geom(
        name="housing_floor",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[sx / 2 + t, sy / 2 + t, t / 2],
        pos=[0, 0, -depth - t / 2],
        material="housing",
        **vis,
    )
    for k, (px, py, hx, hy) in enumerate(
        [
            (sx / 2 + t / 2, 0, t / 2, sy / 2 + t),
            (-sx / 2 - t / 2, 0, t / 2, sy / 2 + t),
            (0, sy / 2 + t / 2, sx / 2, t / 2),
            (0, -sy / 2 - t / 2, sx / 2, t / 2),
        ]
    ):
        housing.add_geom(
            name=f"housing_side_{k}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[hx, hy, (depth + wt / 2) / 2],
            pos=[px, py, (wt / 2 - depth) / 2],
            material="housing",
            **vis,
        )
    # Body wall: skin slab with holes at the incision and the two ports.
    # 1 cm cells keep the mesh light for the software rasteriser (~4k triangles).
    holes = [(0.0, 0.0, 0.012)] + [(px, py, 0.01) for px, py in ph.port_offsets]
    verts, faces = _wall_mesh(sx, sy, wt, holes)
    mesh = spec.add_mesh(name="body_wall")
    mesh.uservert = verts.ravel().tolist()
    mesh.userface = faces.ravel().tolist()
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    housing.add_geom(name="body_wall", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="body_wall", material="skin", **vis)

    # Ports: dark rings in the wall; sites mark the pivot points of the instruments.
    for site, (px, py) in zip(PORT_SITES, ph.port_offsets, strict=True):
        housing.add_site(name=site, pos=[px, py, 0.0], size=[0.003, 0, 0], group=4)
        housing.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[0.009, wt / 2 + 0.004, 0],
            pos=[px, py, 0.0],
            material="port",
            **vis,
        )
    housing.add_site(name="incision_rest", pos=[0, 0, 0], size=[0.003, 0, 0], group=4)

    # Tissue floor and organ.
    zt = -ph.tissue_depth
    housing.add_geom(
        name="tissue",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[sx / 2, sy / 2, (depth - ph.tissue_depth) / 2],
        pos=[0, 0, (zt - depth) / 2],
        material="tissue",
        **vis,
    )
    organ = housing.add_body(name=ORGAN_BODY, pos=[0.045, -0.035, zt])
    organ.add_geom(
        name="organ", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.06, 0.045, 0.02], material="organ", **vis
    )
    # Suture needle: a half circle of wire lying on the tissue.
    needle = housing.add_body(name=NEEDLE_BODY, pos=[-0.035, 0.05, zt + 0.0008])
    nr, nseg = 0.009, 10
    pts = [(nr * math.cos(math.pi * k / nseg), nr * math.sin(math.pi * k / nseg), 0.0) for k in range(nseg + 1)]
    for k in range(nseg):
        needle.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*pts[k], *pts[k + 1]],
            size=[0.0005, 0, 0],
            material="metal",
            **vis,
        )
    needle.add_site(name="needle_center", pos=[0, nr / 2, 0], size=[0.002, 0, 0], group=4)
    for name, (px, py, yaw) in zip(GAUZE_BODIES, [(0.06, 0.065, 0.3), (-0.075, -0.06, -0.5)], strict=True):
        g = housing.add_body(name=name, pos=[px, py, zt + 0.0015], quat=[math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])
        g.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.025, 0.02, 0.0015], material="gauze", **vis)
    return housing
