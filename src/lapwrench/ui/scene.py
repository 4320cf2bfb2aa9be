"""The 3D scene of the page: the MuJoCo model's geoms drawn in viser, posed from the session's
snapshots, with the RCM point and the force arrows.

Each MuJoCo body becomes a viser frame and its geoms children at their fixed local poses, so an
update sends one pose per body that moved. The primitives (box, sphere, ellipsoid, cylinder,
capsule) are built with trimesh, meshes taken from the model; colours from the materials
(textures are not drawn). The floor plane is replaced by a grid.

Arrows, one per force, drawn at :data:`ARROW_SCALE` m per newton from where each acts: the hand on
the handle, every cue's force at its own point (rcm at p_R, interaction at the handle, tracking at
the camera, the others at p_G) and the trocar's force on the shaft at the incision.
"""

from __future__ import annotations

import colorsys
from typing import Any

import mujoco
import numpy as np

from lapwrench.ui.snapshot import Snapshot

ARROW_SCALE = 0.01  # m per N: a 10 N force is a 10 cm arrow
# Arrows are re-sent when an end moved more than this (m; 0.2 N): the F/T noise alone would re-send
# them every frame, and each re-send rebuilds their meshes in the browser.
ARROW_RESEND = 0.002
HAND_COLOR = (230, 60, 60)
TROCAR_COLOR = (250, 170, 30)
_KNOWN_CUE_COLORS = {"rcm": (60, 200, 90), "interaction": (60, 120, 240), "tracking": (200, 60, 220),
                     "viscous": (150, 150, 150)}
# A pose is re-sent when it moved more than this since it was last sent (m, or quaternion units:
# 0.2 mm, about 0.02°), well below a pixel of the page's scene; each update sent costs the browser
# a WebGL frame (software-rendered on a machine without a GPU), and a slow drift is still sent
# once it adds up to this.
_MOVED = 2e-4


def cue_color(name: str, index: int) -> tuple[int, int, int]:
    """A cue's arrow and plot colour: fixed for the paper's cues, spread over the hues for the others."""
    if name in _KNOWN_CUE_COLORS:
        return _KNOWN_CUE_COLORS[name]
    r, g, b = colorsys.hsv_to_rgb((0.13 + 0.29 * index) % 1.0, 0.8, 0.9)
    return round(255 * r), round(255 * g), round(255 * b)


def geom_mesh(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices, faces) of geom ``g`` in its own frame, or None for a type not drawn (plane, ...)."""
    import trimesh

    t = int(model.geom_type[g])
    s = model.geom_size[g]
    G = mujoco.mjtGeom
    if t == G.mjGEOM_BOX:
        m = trimesh.creation.box(extents=2.0 * s)
    elif t == G.mjGEOM_SPHERE:
        m = trimesh.creation.icosphere(subdivisions=2, radius=s[0])
    elif t == G.mjGEOM_ELLIPSOID:
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.apply_scale(s)
    elif t == G.mjGEOM_CYLINDER:
        m = trimesh.creation.cylinder(radius=s[0], height=2.0 * s[1], sections=24)
    elif t == G.mjGEOM_CAPSULE:
        m = trimesh.creation.capsule(radius=s[0], height=2.0 * s[1], count=[12, 12])
    elif t == G.mjGEOM_MESH:
        i = int(model.geom_dataid[g])
        va, vn = model.mesh_vertadr[i], model.mesh_vertnum[i]
        fa, fn = model.mesh_faceadr[i], model.mesh_facenum[i]
        return model.mesh_vert[va:va + vn].astype(np.float32), model.mesh_face[fa:fa + fn].astype(np.int32)
    else:
        return None
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.int32)


def geom_color(model: mujoco.MjModel, g: int) -> tuple[tuple[int, int, int], float]:
    """(RGB 0-255, opacity) of geom ``g``: its material's colour if it has one."""
    mat = int(model.geom_matid[g])
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[g]
    rgb = tuple(round(255 * float(c)) for c in rgba[:3])
    return (rgb[0], rgb[1], rgb[2]), float(rgba[3])


def force_segments(snapshot: Snapshot, scale: float = ARROW_SCALE) -> tuple[list[str], np.ndarray]:
    """(names, (N, 2, 3) start/end points) of the arrows: hand, each cue, trocar."""
    names = ["hand"]
    starts, forces = [snapshot.hand_point], [snapshot.hand_force]
    for name, (point, force) in snapshot.cue_forces.items():
        names.append(name)
        starts.append(point)
        forces.append(force)
    names.append("trocar")
    starts.append(snapshot.incision)
    forces.append(snapshot.trocar_force)
    p = np.asarray(starts, float)
    f = np.asarray(forces, float)
    return names, np.stack([p, p + scale * f], axis=1)


class SceneDrawer:
    """Draws a model's geoms in a viser scene and moves them with each :class:`Snapshot`."""

    def __init__(self, server: Any, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.server = server
        self.model = model
        sc = server.scene
        sc.set_up_direction("+z")
        sc.add_grid("/grid", width=2.0, height=2.0, cell_size=0.1, section_size=0.5)
        self._frames: dict[int, Any] = {}
        self._sent: dict[int, np.ndarray] = {}
        for b in range(1, model.nbody):
            self._frames[b] = sc.add_frame(f"/sim/b{b}", show_axes=False, position=data.xpos[b], wxyz=data.xquat[b])
        for g in range(model.ngeom):
            self._add_geom(g)
        self._rcm = sc.add_icosphere("/rcm_point", radius=0.006, color=(255, 40, 40))
        sc.add_label("/rcm_point/label", "p_R", position=(0.0, 0.0, 0.012))
        self._arrows: Any = None
        self._arrow_names: list[str] = []

    def _add_geom(self, g: int) -> None:
        m = self.model
        b = int(m.geom_bodyid[g])
        if int(m.geom_group[g]) > 2 or (b == 0 and int(m.geom_type[g]) == mujoco.mjtGeom.mjGEOM_PLANE):
            return
        mesh = geom_mesh(m, g)
        color, alpha = geom_color(m, g)
        if mesh is None or alpha <= 0.0:
            return
        parent = f"/sim/b{b}" if b > 0 else "/sim/world"
        self.server.scene.add_mesh_simple(
            f"{parent}/g{g}", mesh[0], mesh[1], color=color, opacity=None if alpha >= 1.0 else alpha,
            position=m.geom_pos[g], wxyz=m.geom_quat[g], cast_shadow=False, receive_shadow=False,
        )

    def update(self, snapshot: Snapshot, colors: dict[str, tuple[int, int, int]]) -> int:
        """Move the bodies that moved, the RCM point and the arrows; returns the poses sent."""
        sent = 0
        for b, frame in self._frames.items():
            pose = np.concatenate([snapshot.body_pos[b], snapshot.body_quat[b]])
            last = self._sent.get(b)
            if last is not None and np.max(np.abs(pose - last)) < _MOVED:
                continue
            frame.position = pose[:3]
            frame.wxyz = pose[3:]
            self._sent[b] = pose
            sent += 1
        if np.max(np.abs(np.asarray(self._rcm.position) - snapshot.p_R)) > _MOVED:
            self._rcm.position = snapshot.p_R
        names, segments = force_segments(snapshot)
        rgb = np.array([HAND_COLOR if n == "hand" else TROCAR_COLOR if n == "trocar" else colors.get(n, (128, 128, 128))
                        for n in names], np.uint8)
        if self._arrows is None or names != self._arrow_names:
            if self._arrows is not None:
                self._arrows.remove()
            self._arrows = self.server.scene.add_arrows("/forces", segments.astype(np.float32), rgb,
                                                        shaft_radius=0.002, head_radius=0.005, head_length=0.012)
            self._arrow_names = names
        elif np.max(np.abs(self._arrows.points - segments)) > ARROW_RESEND:
            self._arrows.points = segments.astype(np.float32)
        return sent
