"""The arm and the laparoscope's links in MuJoCo, built from the shared robot description.

The arm and the laparoscope come from :func:`lapwrench.robot.description.build_urdf`, i.e. the very
text Pinocchio loads, so the controller's model and the simulated robot agree (tests/sim checks the
mass matrix and the flange Jacobian). Static scope links (``lap_E``, ``lap_H``, ``lap_C`` ...) are
kept as separate bodies so their frames exist in MuJoCo too. Base frame = MuJoCo world frame (the
arm's root link sits at the origin).

Also here: the arm's torque limits and default initial configuration, link visuals for descriptions
without geometry, the Franka-like joint position servos and the flange pose at q0.
"""

from __future__ import annotations

import re
from functools import cache

import mujoco
import numpy as np

from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import FRAME_E, RobotKind, ScopeGeometry, build_urdf
from lapwrench.robot.limits import joint_torque_limits

#: The Panda's joint torque limits (N m), one per joint (each scene clips to its own robot's,
#: :func:`~lapwrench.robot.limits.joint_torque_limits`, from the arm's spec).
TAU_MAX = joint_torque_limits("panda")


def default_initial_configuration(kind: RobotKind = "panda") -> np.ndarray:
    """Initial joint configuration q0 (rad): scope pointing down into the abdomen (the robot spec's
    ``sim_start_pose``: flange 0.482 m above the base, 0.5 m in front, z_E = -z_B)."""
    return np.array(arm_spec(kind).sim_start_pose, dtype=float)


def _mujoco_urdf_text(kind: RobotKind, scope: ScopeGeometry) -> str:
    """``build_urdf`` text with a ``<mujoco>`` compiler block: keep static links as bodies, keep paths."""
    text = build_urdf(kind, scope)
    ext = '<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false"/></mujoco>'
    text, n = re.subn(r"(<robot\b[^>]*>)", r"\1" + ext, text, count=1)
    if n != 1:
        raise ValueError("robot description has no <robot> element")
    return text


def _descendants(body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
    """Every body below ``body`` (depth first, ``body`` itself excluded)."""
    out: list[mujoco.MjsBody] = []
    stack = list(body.bodies)
    while stack:
        b = stack.pop()
        out.append(b)
        stack.extend(b.bodies)
    return out


def build_arm_spec(
    kind: RobotKind = "panda", scope: ScopeGeometry | None = None, *, armature: float = 0.0
) -> mujoco.MjSpec:
    """MjSpec of the arm + laparoscope only, straight from ``build_urdf`` text.

    Joint friction is removed (Franka's link-side torque sensors do not see it), ``armature`` is set
    on every arm joint, every geom is made visual-only and gravity compensation is enabled on all
    arm bodies (applied through the joint actuators, so it counts in tau_J and is clipped with it).
    """
    scope = scope or ScopeGeometry()
    spec = mujoco.MjSpec.from_string(_mujoco_urdf_text(kind, scope))
    spec.modelname = f"{kind}_laparoscope"
    spec.compiler.discardvisual = False  # the URDF's .dae visuals are already gone; keep our visual geoms
    arm = arm_spec(kind)
    for name in arm.joint_names:
        j = spec.joint(name)
        j.frictionloss = 0.0
        j.armature = armature
        j.actgravcomp = True
    rgba = arm.look.rgba
    for g in spec.geoms:
        g.contype = 0
        g.conaffinity = 0
        g.group = 1
        g.rgba = rgba
    for b in _descendants(spec.worldbody):
        b.gravcomp = 1.0
        if b.mass == 0.0 and not list(b.geoms):
            # Massless frame bodies: put the (empty) inertial frame at the body origin, so that
            # xfrc_applied on e.g. lap_H acts at the lap_H origin (MuJoCo applies it at xipos).
            b.ipos = [0.0, 0.0, 0.0]
    return spec


def add_link_capsules(spec: mujoco.MjSpec, kind: RobotKind) -> None:
    """Primitive visuals for arm links that come without geometry (the FR3 description): capsules of the
    spec's radius between successive joints, a disc at the flange."""
    arm = arm_spec(kind)
    rgba, radius = arm.look.rgba, arm.look.capsule_radius
    for b in _descendants(spec.worldbody):
        if b.name.startswith("lap_") or list(b.geoms):
            continue
        for child in b.bodies:
            d = np.asarray(child.pos, float)
            if np.linalg.norm(d) > 0.02 and not child.name.startswith("lap_"):
                b.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    fromto=[0, 0, 0, *d],
                    size=[radius, 0, 0],
                    rgba=rgba,
                    contype=0,
                    conaffinity=0,
                    group=1,
                    mass=0.0,
                    density=0.0,
                )
        if b.name == arm.flange_link:
            b.add_geom(
                type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[0.9 * radius, 0.02, 0],
                pos=[0, 0, -0.02],
                rgba=rgba,
                contype=0,
                conaffinity=0,
                group=1,
                density=0.0,
            )


def add_joint_servos(spec: mujoco.MjSpec, kind: RobotKind) -> None:
    """One joint position servo per arm joint, its joint torque clipped to the robot's torque limit
    (the spec's table)."""
    # Franka-like joint position servo: tau = kp (q_ref - q) + kv (dq_ref - dq), plus gravity
    # compensation (jnt actgravcomp); the SimWorld sets kp/kv. The sum is clipped to tau_max.
    for name, tau in zip(arm_spec(kind).joint_names, joint_torque_limits(kind), strict=True):
        j = spec.joint(name)
        j.actfrclimited = True
        j.actfrcrange = [-tau, tau]
        a = spec.add_actuator(name=f"servo_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.gainprm[0] = 1.0
        a.biasprm[1] = -1.0
        a.ctrllimited = False


@cache
def flange_pose_at(kind: RobotKind, scope: ScopeGeometry, q0: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """World position and rotation matrix of lap_E at ``q0`` (cached: compiles the bare arm once)."""
    spec = build_arm_spec(kind, scope)
    m = spec.compile()
    d = mujoco.MjData(m)
    adr = [m.joint(n).qposadr[0] for n in arm_spec(kind).joint_names]
    d.qpos[adr] = q0
    mujoco.mj_kinematics(m, d)
    b = m.body(FRAME_E).id
    return d.xpos[b].copy(), d.xmat[b].reshape(3, 3).copy()
