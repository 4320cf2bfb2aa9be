"""MuJoCo world for the laparoscope-holding robot, built from the shared robot description.

The arm and the laparoscope come from :func:`lapwrench.robot.description.build_urdf`, i.e. the very
text Pinocchio loads, so the controller's model and the simulated robot agree (tests/sim checks the
mass matrix and the flange Jacobian). Static scope links (``lap_E``, ``lap_H``, ``lap_C`` ...) are
kept as separate bodies so their frames exist in MuJoCo too.

Base frame = MuJoCo world frame (the arm's root link sits at the origin).

The world contains:

- the laparoscope: 10 mm x 0.29 m shaft and a handle (visual geoms on the URDF bodies), a camera
  at the tip with the paper's pinhole intrinsics (image u along x_C, v along y_C, looking along
  +z_C, OpenCV convention; checked by rendering to within 0.3 px) and a tip light;
- an abdominal phantom (body ``housing``): a box shell on two horizontal spring-damper slides so a
  sustained lateral load displaces it (Fig. 5 disturbance), a body wall (visual mesh with holes),
  a textured tissue floor and organ, a suture needle and two gauze pads;
- the incision (body ``incision``): a small body on two spring-damper slides in the wall plane
  (the elastic abdominal wall, ``wall_stiffness`` N/m) carrying a trocar: a ball-jointed pivot and
  a sleeve sliding along the pivot's axis, welded to the shaft by a soft equality constraint
  (``trocar_weld``, solref time constant 2 ms = 4 physics steps). The shaft thus slides and rolls
  freely (frictionless) through the incision point, while any lateral offset of the shaft from the
  unloaded incision stretches the wall spring. The wall-on-scope force is the weld's constraint
  force from the solver: smooth, isotropic, zero when the shaft sits at the unloaded incision.
  (A ring of capsule contacts was tried first: its polygonal normals quantise the force
  direction and make it jump by ~2 N when the shaft slides from one segment to the next.)
- two instruments (mocap bodies ``instrument_left``/``instrument_right``), black shafts with
  metallic jaws, posed by the caller through their own ports in the wall.

Nothing collides (contype = conaffinity = 0 everywhere): the trocar constraint is the only
interaction between robot and phantom; arm self-collision is not simulated.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from functools import cache

import mujoco
import numpy as np

from lapwrench.config import CameraConfig, Config
from lapwrench.robot.description import (
    ARM_SPECS,
    FRAME_C,
    FRAME_E,
    FRAME_H,
    RobotKind,
    ScopeGeometry,
    build_urdf,
)

# Names other modules may rely on.
FT_FORCE_SENSOR = "handle_ft_force"
FT_TORQUE_SENSOR = "handle_ft_torque"
CAMERA_NAME = "lap_camera"
OVERVIEW_CAMERA_NAME = "overview"
TROCAR_BODY = "trocar"
SLEEVE_BODY = "trocar_sleeve"
TROCAR_WELD = "trocar_weld"
HANDLE_BODY = FRAME_H
HOUSING_BODY = "housing"
INCISION_BODY = "incision"
INCISION_JOINTS = ("incision_x", "incision_y")
HOUSING_JOINTS = ("housing_x", "housing_y")
RING_GEOM_PREFIX = "incision_ring_"
INSTRUMENT_BODIES = ("instrument_left", "instrument_right")
PORT_SITES = ("port_left", "port_right")
INSTRUMENT_TIP_SITES = ("instrument_left_tip", "instrument_right_tip")
NEEDLE_BODY = "needle"
GAUZE_BODIES = ("gauze_1", "gauze_2")
ORGAN_BODY = "organ"

#: Franka joint torque limits (N m), joints 1-7.
TAU_MAX = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])

#: Default initial arm configuration: flange 0.482 m above the base, 0.5 m in front, scope
#: pointing straight down (z_E = -z_B). Identical for Panda and FR3 (same kinematics); at least
#: 0.9 rad from every joint limit.
_DEFAULT_Q0 = (0.0, -0.1774, 0.0, -2.1379, 0.0, 1.9606, math.pi / 4)

_ARM_RGBA = {"panda": (0.92, 0.92, 0.94, 1.0), "fr3": (0.93, 0.93, 0.93, 1.0)}


def default_initial_configuration(kind: RobotKind = "panda") -> np.ndarray:
    """Initial joint configuration q0 (rad): scope pointing down into the abdomen."""
    if kind not in ARM_SPECS:
        raise ValueError(f"unknown robot {kind!r}; choose one of {tuple(ARM_SPECS)}")
    return np.array(_DEFAULT_Q0, dtype=float)


_PAPER_CAMERA = CameraConfig()


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the laparoscope camera, in pixels (defaults: the configuration's,
    i.e. the paper's Sec. IV-A values)."""

    width: int = _PAPER_CAMERA.width
    height: int = _PAPER_CAMERA.height
    fx: float = _PAPER_CAMERA.fx
    fy: float = _PAPER_CAMERA.fy
    u0: float = _PAPER_CAMERA.u0
    v0: float = _PAPER_CAMERA.v0

    @classmethod
    def from_config(cls, cam: CameraConfig) -> CameraIntrinsics:
        return cls(cam.width, cam.height, cam.fx, cam.fy, cam.u0, cam.v0)

    def project(self, p_c: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u, v) of points given in the camera frame {C} (shape (..., 3))."""
        p = np.asarray(p_c, dtype=float)
        z = p[..., 2]
        return np.stack([self.fx * p[..., 0] / z + self.u0, self.fy * p[..., 1] / z + self.v0], axis=-1)


@dataclass(frozen=True)
class PhantomConfig:
    """Abdominal phantom parameters (SI units).

    ``wall_stiffness`` is the lateral stiffness of the abdominal wall at the incision (~1 N/mm), in
    series with the ring contact. ``housing_stiffness`` holds the phantom on the table: a
    lateral load F shifts a free housing by F / housing_stiffness.
    """

    wall_stiffness: float = 1000.0
    wall_damping: float = 30.0
    incision_mass: float = 0.1
    trocar_mass: float = 0.03
    trocar_timeconst: float = 0.002
    ring_segments: int = 16
    ring_tube_radius: float = 0.003
    housing_mass: float = 3.0
    housing_stiffness: float = 2000.0
    housing_damping: float = 160.0
    size_x: float = 0.36
    size_y: float = 0.32
    depth: float = 0.17
    wall_thickness: float = 0.024
    tissue_depth: float = 0.145
    port_offsets: tuple[tuple[float, float], tuple[float, float]] = ((0.03, 0.09), (0.03, -0.09))

    def __post_init__(self) -> None:
        positive = (
            "wall_stiffness",
            "wall_damping",
            "incision_mass",
            "trocar_mass",
            "trocar_timeconst",
            "ring_tube_radius",
            "housing_mass",
            "housing_stiffness",
            "housing_damping",
            "size_x",
            "size_y",
            "depth",
            "wall_thickness",
            "tissue_depth",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"phantom.{name} must be a positive finite number, got {value!r}")
        if self.ring_segments < 6:
            raise ValueError(f"phantom.ring_segments must be >= 6, got {self.ring_segments!r}")
        if self.tissue_depth >= self.depth:
            raise ValueError("phantom.tissue_depth must be smaller than phantom.depth")


@dataclass(frozen=True)
class SceneConfig:
    """Everything that defines the simulated world.

    ``armature`` (kg m^2) is the reflected rotor inertia added to every arm joint, as in MuJoCo
    Menagerie's Franka models; set 0 for a pure rigid-body arm (the mass matrix then equals
    Pinocchio's). ``rcm_lambda0`` places the incision at ``lambda0 * L`` from lap_E along the shaft
    in the initial configuration (paper eq. 18).
    """

    kind: RobotKind = "panda"
    scope: ScopeGeometry = field(default_factory=ScopeGeometry)
    phantom: PhantomConfig = field(default_factory=PhantomConfig)
    camera: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    timestep: float = 0.0005
    armature: float = 0.1
    q0: tuple[float, ...] | None = None
    rcm_lambda0: float = 0.8

    def __post_init__(self) -> None:
        if self.kind not in ARM_SPECS:
            raise ValueError(f"unknown robot {self.kind!r}; choose one of {tuple(ARM_SPECS)}")
        if not (0.0 < self.timestep <= 0.001 and 0.001 / self.timestep == round(0.001 / self.timestep)):
            raise ValueError(f"timestep must divide the 1 ms control period, got {self.timestep!r}")
        if not (math.isfinite(self.armature) and self.armature >= 0.0):
            raise ValueError(f"armature must be >= 0, got {self.armature!r}")
        if not (0.0 < self.rcm_lambda0 < 1.0):
            raise ValueError(f"rcm_lambda0 must lie in (0, 1), got {self.rcm_lambda0!r}")
        if self.q0 is not None and len(self.q0) != 7:
            raise ValueError(f"q0 needs 7 joint values, got {len(self.q0)}")

    @classmethod
    def from_config(cls, cfg: Config) -> SceneConfig:
        """The world a controller configuration runs in: same robot, scope, camera and RCM place."""
        return cls(
            kind=cfg.robot.kind,
            scope=ScopeGeometry.from_config(cfg.scope),
            camera=CameraIntrinsics.from_config(cfg.camera),
            rcm_lambda0=cfg.scope.lambda0,
        )

    def initial_configuration(self) -> np.ndarray:
        """q0 of this config (the default one unless given)."""
        return default_initial_configuration(self.kind) if self.q0 is None else np.array(self.q0, float)


@dataclass
class Scene:
    """A compiled world: the spec, the model and the geometry other modules need."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    config: SceneConfig
    q0: np.ndarray
    incision_position: np.ndarray
    arm_joint_names: tuple[str, ...]

    @property
    def arm_qpos_adr(self) -> np.ndarray:
        """qpos addresses of the 7 arm joints."""
        return np.array([self.model.joint(n).qposadr[0] for n in self.arm_joint_names])

    @property
    def arm_dof_adr(self) -> np.ndarray:
        """qvel/dof addresses of the 7 arm joints."""
        return np.array([self.model.joint(n).dofadr[0] for n in self.arm_joint_names])


# --------------------------------------------------------------------------------------------
# Arm


def _mujoco_urdf_text(kind: RobotKind, scope: ScopeGeometry) -> str:
    text = build_urdf(kind, scope)
    ext = '<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false"/></mujoco>'
    text, n = re.subn(r"(<robot\b[^>]*>)", r"\1" + ext, text, count=1)
    if n != 1:
        raise ValueError("robot description has no <robot> element")
    return text


def _descendants(body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
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
    arm = ARM_SPECS[kind]
    for name in arm.joint_names:
        j = spec.joint(name)
        j.frictionloss = 0.0
        j.armature = armature
        j.actgravcomp = True
    rgba = _ARM_RGBA[kind]
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


def _add_link_capsules(spec: mujoco.MjSpec, kind: RobotKind) -> None:
    """Primitive visuals for arm links that come without geometry (the FR3 description)."""
    arm = ARM_SPECS[kind]
    rgba = _ARM_RGBA[kind]
    for b in _descendants(spec.worldbody):
        if b.name.startswith("lap_") or list(b.geoms):
            continue
        for child in b.bodies:
            d = np.asarray(child.pos, float)
            if np.linalg.norm(d) > 0.02 and not child.name.startswith("lap_"):
                b.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    fromto=[0, 0, 0, *d],
                    size=[0.045, 0, 0],
                    rgba=rgba,
                    contype=0,
                    conaffinity=0,
                    group=1,
                    mass=0.0,
                    density=0.0,
                )
        if b.name == arm.flange_link or b.name.endswith("link7"):
            b.add_geom(
                type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[0.04, 0.02, 0],
                pos=[0, 0, -0.02],
                rgba=rgba,
                contype=0,
                conaffinity=0,
                group=1,
                density=0.0,
            )


def _dress_scope(spec: mujoco.MjSpec, scope: ScopeGeometry, cam: CameraIntrinsics) -> None:
    """Laparoscope visuals, the shaft contact capsule, the tip camera and the tip light."""
    for g in list(spec.body("lap_shaft").geoms) + list(spec.body("lap_handle").geoms):
        g.contype = 0
        g.conaffinity = 0
        g.group = 1
    for g in spec.body("lap_shaft").geoms:
        g.rgba = [0.72, 0.74, 0.78, 1.0]
        g.material = "metal"
    for g in spec.body("lap_handle").geoms:
        g.rgba = [0.15, 0.15, 0.17, 1.0]
    tip = spec.body(FRAME_C)
    # MuJoCo cameras look along -z with y up; {C} looks along +z with y down: rotate pi about x.
    c = tip.add_camera(name=CAMERA_NAME, pos=[0, 0, 0], quat=[0, 1, 0, 0])
    c.resolution = [cam.width, cam.height]
    c.sensor_size = [cam.width * 1e-5, cam.height * 1e-5]  # 10 um "pixels"; only ratios matter
    c.focal_pixel = [cam.fx, cam.fy]
    # MuJoCo's principal point is an offset from the sensor centre in OpenGL window coordinates,
    # whose pixel centres sit at +0.5 (OpenCV's at integers); the signs were checked by rendering.
    c.principal_pixel = [cam.width / 2.0 - (cam.u0 + 0.5), cam.height / 2.0 - (cam.v0 + 0.5)]
    tip.add_light(
        name="scope_light",
        pos=[0, 0, 0.002],
        dir=[0, 0, 1],
        type=mujoco.mjtLightType.mjLIGHT_SPOT,
        cutoff=70.0,
        exponent=2.0,
        diffuse=[0.9, 0.88, 0.82],
        specular=[0.3, 0.3, 0.3],
        attenuation=[1.0, 0.0, 0.0],
        castshadow=False,
    )
    spec.body(FRAME_E).add_site(name="lap_E_site", size=[0.004, 0, 0], group=4)
    spec.body(FRAME_H).add_site(name="lap_H_site", size=[0.004, 0, 0], group=4)
    # The handle F/T sensor: the force/torque transmitted between the hand grip (lap_H) and the
    # scope, in the lap_H frame (MuJoCo's force/torque sensors read the body-parent interaction).
    ft = ((FT_FORCE_SENSOR, mujoco.mjtSensor.mjSENS_FORCE), (FT_TORQUE_SENSOR, mujoco.mjtSensor.mjSENS_TORQUE))
    for name, kind in ft:
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="lap_H_site")


# --------------------------------------------------------------------------------------------
# Textures and materials


def _organ_texture(size: int = 512, seed: int = 7) -> np.ndarray:
    """Procedural tissue texture: pink-red base, smooth mottling, fine vessels, fat patches (tileable)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    noise = np.zeros((size, size))
    for k in range(1, 8):
        for _ in range(3):
            fx, fy = rng.integers(1, 4 * k + 2, size=2)
            ph = rng.uniform(0, 2 * np.pi, size=2)
            noise += np.sin(2 * np.pi * fx * x + ph[0]) * np.sin(2 * np.pi * fy * y + ph[1]) / k
    noise = (noise - noise.min()) / (np.ptp(noise) + 1e-9)
    base = np.array([168.0, 58.0, 56.0])
    light = np.array([226.0, 132.0, 118.0])
    img = base + (light - base) * noise[..., None]
    img *= rng.uniform(0.94, 1.06, size=(size, size, 1))  # fine grain
    fat = noise > 0.84
    img[fat] = 0.45 * img[fat] + 0.55 * np.array([232.0, 200.0, 128.0])
    vessel = np.array([120.0, 28.0, 48.0])
    for _ in range(10):  # vessels: smooth, branching-free random walks, wrapped (the texture tiles)
        p = rng.uniform(0, size, size=2)
        ang = rng.uniform(0, 2 * np.pi)
        w = int(rng.integers(0, 2))
        for _ in range(400):
            ang += rng.normal(0.0, 0.12)
            p = (p + np.array([np.cos(ang), np.sin(ang)])) % size
            i0, j0 = int(p[1]), int(p[0])
            rows = np.arange(i0 - w, i0 + w + 1) % size
            cols = np.arange(j0 - w, j0 + w + 1) % size
            img[np.ix_(rows, cols)] = 0.7 * img[np.ix_(rows, cols)] + 0.3 * vessel
    return np.clip(img, 0, 255).astype(np.uint8)


def _add_materials(spec: mujoco.MjSpec) -> None:
    tex = _organ_texture()
    t = spec.add_texture(
        name="tissue",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        width=tex.shape[1],
        height=tex.shape[0],
        nchannel=3,
    )
    t.data = tex.tobytes()
    m = spec.add_material(name="tissue", specular=0.35, shininess=0.6, texrepeat=[1, 1])
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "tissue"
    m = spec.add_material(name="organ", specular=0.5, shininess=0.7, texrepeat=[1, 1], rgba=[0.95, 0.8, 0.8, 1])
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "tissue"
    spec.add_texture(
        name="gauze",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=64,
        height=64,
        rgb1=[0.97, 0.97, 0.95],
        rgb2=[0.86, 0.86, 0.84],
    )
    m = spec.add_material(name="gauze", texrepeat=[12, 12], specular=0.05)
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "gauze"
    spec.add_material(name="metal", rgba=[0.78, 0.79, 0.82, 1], specular=1.0, shininess=0.9)
    spec.add_material(name="black", rgba=[0.04, 0.04, 0.05, 1], specular=0.4, shininess=0.5)
    spec.add_material(name="skin", rgba=[0.93, 0.76, 0.66, 1], specular=0.2, shininess=0.3)
    spec.add_material(name="housing", rgba=[0.32, 0.42, 0.55, 1], specular=0.2)
    spec.add_material(name="port", rgba=[0.2, 0.2, 0.22, 1], specular=0.3)
    spec.add_texture(
        name="floor",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=256,
        height=256,
        rgb1=[0.55, 0.57, 0.6],
        rgb2=[0.45, 0.47, 0.5],
    )
    m = spec.add_material(name="floor", texrepeat=[8, 8], reflectance=0.0)
    m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor"


# --------------------------------------------------------------------------------------------
# Phantom


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


def _add_phantom(spec: mujoco.MjSpec, cfg: SceneConfig, incision: np.ndarray, scope_quat: np.ndarray) -> None:
    ph = cfg.phantom
    scope = cfg.scope
    vis = {"contype": 0, "conaffinity": 0, "group": 2, "density": 0.0}
    world = spec.worldbody
    sx, sy, depth, wt = ph.size_x, ph.size_y, ph.depth, ph.wall_thickness

    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.05], material="floor", **vis)
    # Table under the phantom.
    table_top = incision[2] - depth - 0.01
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.3, 0.3, table_top / 2],
        pos=[incision[0], incision[1], table_top / 2],
        rgba=[0.6, 0.6, 0.62, 1],
        **vis,
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
    depth = cfg.rcm_lambda0 * scope.length
    # data: anchor in body2 (shaft) frame = the incision point; the same point in body1 (sleeve)
    # frame = its origin; relative orientation = identity; torquescale.
    eq.data = [0.0, 0.0, depth, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    eq.solref = [ph.trocar_timeconst, 1.0]
    eq.solimp = [0.95, 0.99, 0.001, 0.5, 2.0]


def _add_instruments(spec: mujoco.MjSpec, incision: np.ndarray, ph: PhantomConfig) -> None:
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


def _instrument_pose_through_port_numpy(
    port: np.ndarray, tip: np.ndarray, roll: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`instrument_pose_through_port` written with numpy's vector functions (the tests' reference)."""
    z = np.asarray(tip, float) - np.asarray(port, float)
    nz = np.linalg.norm(z)
    if nz < 1e-6:
        raise ValueError("instrument tip coincides with its port")
    z /= nz
    ref = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    R = np.column_stack([x, y, z])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    return np.asarray(tip, float).copy(), quat


# --------------------------------------------------------------------------------------------
# Whole world


@cache
def _flange_pose_at(kind: RobotKind, scope: ScopeGeometry, q0: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    spec = build_arm_spec(kind, scope)
    m = spec.compile()
    d = mujoco.MjData(m)
    adr = [m.joint(n).qposadr[0] for n in ARM_SPECS[kind].joint_names]
    d.qpos[adr] = q0
    mujoco.mj_kinematics(m, d)
    b = m.body(FRAME_E).id
    return d.xpos[b].copy(), d.xmat[b].reshape(3, 3).copy()


def _scope_quat_at(cfg: SceneConfig) -> np.ndarray:
    """World orientation (quat wxyz) of lap_E at q0."""
    _, R = _flange_pose_at(cfg.kind, cfg.scope, tuple(cfg.initial_configuration().tolist()))
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    return quat


def incision_position_for(cfg: SceneConfig) -> np.ndarray:
    """Rest position of the incision: lambda0 * L along the shaft from lap_E at q0 (eq. 18)."""
    p_e, R = _flange_pose_at(cfg.kind, cfg.scope, tuple(cfg.initial_configuration().tolist()))
    return p_e + cfg.rcm_lambda0 * cfg.scope.length * R[:, 2]


def build_scene(config: SceneConfig | None = None) -> Scene:
    """Compile the complete world (arm + scope + phantom + instruments) for ``config``."""
    cfg = config or SceneConfig()
    q0 = cfg.initial_configuration()
    incision = incision_position_for(cfg)
    spec = build_arm_spec(cfg.kind, cfg.scope, armature=cfg.armature)
    spec.modelname = f"lapwrench_{cfg.kind}"
    _add_materials(spec)
    _add_link_capsules(spec, cfg.kind)
    _dress_scope(spec, cfg.scope, cfg.camera)
    _add_phantom(spec, cfg, incision, _scope_quat_at(cfg))
    _add_instruments(spec, incision, cfg.phantom)

    opt = spec.option
    opt.timestep = cfg.timestep
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.iterations = 50
    opt.tolerance = 1e-10

    # Franka-like joint position servo: tau = kp (q_ref - q) + kv (dq_ref - dq), plus gravity
    # compensation (jnt actgravcomp); the SimWorld sets kp/kv. The sum is clipped to tau_max.
    for name, tau in zip(ARM_SPECS[cfg.kind].joint_names, TAU_MAX, strict=True):
        j = spec.joint(name)
        j.actfrclimited = True
        j.actfrcrange = [-tau, tau]
        a = spec.add_actuator(name=f"servo_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.gainprm[0] = 1.0
        a.biasprm[1] = -1.0
        a.ctrllimited = False

    spec.worldbody.add_light(
        name="room",
        pos=[incision[0] - 0.3, incision[1], 2.0],
        dir=[0.15, 0, -1],
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        diffuse=[0.55, 0.55, 0.55],
        castshadow=False,
    )
    _add_overview_camera(spec, incision)

    vis = spec.visual
    vis.global_.offwidth = max(1280, cfg.camera.width)
    vis.global_.offheight = max(960, cfg.camera.height)
    vis.quality.shadowsize = 0
    vis.headlight.ambient = [0.25, 0.25, 0.25]
    vis.headlight.diffuse = [0.45, 0.45, 0.45]
    vis.headlight.specular = [0.1, 0.1, 0.1]
    spec.stat.extent = 1.5
    spec.stat.center = [incision[0] / 2, incision[1] / 2, incision[2] / 2]
    vis.map.znear = 0.002 / 1.5  # 2 mm near clip: the scope camera looks at tissue 2-15 cm away
    vis.map.zfar = 10.0

    model = spec.compile()
    return Scene(
        spec=spec,
        model=model,
        config=cfg,
        q0=q0,
        incision_position=incision,
        arm_joint_names=ARM_SPECS[cfg.kind].joint_names,
    )


def _add_overview_camera(spec: mujoco.MjSpec, incision: np.ndarray) -> None:
    """External camera looking at robot and phantom (for figures like the paper's Fig. 5a)."""
    eye = incision + np.array([0.55, -1.0, 0.55])
    target = np.array([incision[0] * 0.6, incision[1], incision[2] + 0.15])
    fwd = target - eye
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    R = np.column_stack([x, y, -fwd])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    spec.worldbody.add_camera(name=OVERVIEW_CAMERA_NAME, pos=list(eye), quat=list(quat), fovy=50.0)
