"""The incision in the abdominal wall and the trocar that holds the scope's shaft in it.

The incision (body ``incision``) is a small body on two spring-damper slides in the wall plane (the
elastic abdominal wall, ``wall_stiffness`` N/m) carrying a trocar: a ball-jointed pivot and a sleeve
sliding along the pivot's axis, welded to the shaft by a soft equality constraint (``trocar_weld``,
solref time constant 2 ms = 4 physics steps). The shaft thus slides and rolls freely (frictionless)
through the incision point, while any lateral offset of the shaft from the unloaded incision
stretches the wall spring. The wall-on-scope force is the weld's constraint force from the solver:
smooth, isotropic, zero when the shaft sits at the unloaded incision. (A ring of capsule contacts
was tried first: its polygonal normals quantise the force direction and make it jump by ~2 N when
the shaft slides from one segment to the next.)
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.scene.names import (
    INCISION_BODY,
    INCISION_JOINTS,
    RING_GEOM_PREFIX,
    SLEEVE_BODY,
    TROCAR_BODY,
    TROCAR_WELD,
)


def add_incision(spec: mujoco.MjSpec, housing: mujoco.MjsBody, cfg: SceneConfig, scope_quat: np.ndarray) -> None:
    """The incision body in the phantom's wall, the trocar on it and its weld to the scope's shaft.

    ``scope_quat`` (wxyz) is lap_E's world orientation at q0: the trocar's axis starts along the shaft.
    """
    ph = cfg.phantom
    scope = cfg.scope
    vis = {"contype": 0, "conaffinity": 0, "group": 2, "density": 0.0}
    # Incision: a body on two spring-damper slides in the wall plane (the elastic abdominal wall)
    # carrying a trocar: a ball-jointed pivot with a sleeve sliding along its axis. The sleeve is
    # welded (soft equality constraint) to the shaft, so the shaft passes through the incision
    # point, slides and rolls freely in it, and the wall spring pushes back on lateral offsets.
    inc = housing.add_body(name=INCISION_BODY, pos=[0, 0, 0])
    inc.explicitinertial = True
    inc.mass = ph.incision_mass
    ri = 0.02
    inc.inertia = [ph.incision_mass * ri**2 / 4] * 2 + [ph.incision_mass * ri**2 / 2]
    for name, axis in zip(INCISION_JOINTS, ([1, 0, 0], [0, 1, 0]), strict=True):
        inc.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=axis,
            stiffness=ph.wall_stiffness,
            damping=ph.wall_damping,
            armature=0.0,
        )
    n = ph.ring_segments
    rt = ph.ring_tube_radius
    R = scope.shaft_diameter / 2 + 0.0005 + rt
    half = R * math.tan(math.pi / n)
    for k in range(n):  # visual incision lips around the shaft
        a = 2 * math.pi * (k + 0.5) / n
        c = np.array([R * math.cos(a), R * math.sin(a), 0.0])
        tdir = np.array([-math.sin(a), math.cos(a), 0.0])
        inc.add_geom(
            name=f"{RING_GEOM_PREFIX}{k}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*(c - half * tdir), *(c + half * tdir)],
            size=[rt, 0, 0],
            rgba=[0.55, 0.2, 0.2, 1],
            **vis,
        )
    inc.add_site(name="incision_center", pos=[0, 0, 0], size=[0.002, 0, 0], group=4)

    m_t = ph.trocar_mass
    trocar = inc.add_body(name=TROCAR_BODY, pos=[0, 0, 0], quat=list(scope_quat))
    trocar.gravcomp = 1.0
    trocar.explicitinertial = True
    trocar.mass = m_t
    trocar.inertia = [m_t * 0.03**2 / 12] * 2 + [m_t * 0.006**2 / 2]
    trocar.add_joint(name="trocar_pivot", type=mujoco.mjtJoint.mjJNT_BALL, armature=1e-5, damping=1e-4)
    sleeve = trocar.add_body(name=SLEEVE_BODY, pos=[0, 0, 0])
    sleeve.gravcomp = 1.0
    sleeve.explicitinertial = True
    sleeve.mass = m_t
    sleeve.inertia = [m_t * 0.03**2 / 12] * 2 + [m_t * 0.006**2 / 2]
    sleeve.add_joint(name="trocar_slide", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], armature=1e-3)
    eq = spec.add_equality(name=TROCAR_WELD, type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY)
    eq.name1 = SLEEVE_BODY
    eq.name2 = "lap_shaft"
    depth = cfg.rcm_lambda0 * scope.length  # eq (18)'s λ0 L in lap_E's own frame: incision_position_for's point
    # data: anchor in body2 (shaft) frame = the incision point; the same point in body1 (sleeve)
    # frame = its origin; relative orientation = identity; torquescale.
    eq.data = [0.0, 0.0, depth, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    eq.solref = [ph.trocar_timeconst, 1.0]
    eq.solimp = [0.95, 0.99, 0.001, 0.5, 2.0]
