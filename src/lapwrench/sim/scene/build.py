"""The whole world: :func:`build_scene` assembles arm, scope, phantom, trocar, instruments, lights and
cameras, sets the physics options and compiles it into a :class:`Scene`.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from lapwrench.rcm.geometry import initial_rcm_point
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.model import ScopeAxis, scope_axis
from lapwrench.sim.scene.arm import add_joint_servos, add_link_capsules, build_arm_spec, flange_pose_at
from lapwrench.sim.scene.camera import add_overview_camera, configure_rendering
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.scene.instruments import add_instruments
from lapwrench.sim.scene.materials import add_materials
from lapwrench.sim.scene.phantom import add_phantom
from lapwrench.sim.scene.scope import dress_scope
from lapwrench.sim.scene.trocar import add_incision


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
        """qpos addresses of the arm joints."""
        return np.array([self.model.joint(n).qposadr[0] for n in self.arm_joint_names])

    @property
    def arm_dof_adr(self) -> np.ndarray:
        """qvel/dof addresses of the arm joints."""
        return np.array([self.model.joint(n).dofadr[0] for n in self.arm_joint_names])


def _scope_quat_at(cfg: SceneConfig) -> np.ndarray:
    """World orientation (quat wxyz) of lap_E at q0."""
    _, R = flange_pose_at(cfg.kind, cfg.scope, tuple(cfg.initial_configuration().tolist()))
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    return quat


def incision_position_for(cfg: SceneConfig) -> np.ndarray:
    """Rest position of the incision: lambda0 * L along the shaft from lap_E at q0, eq (18)'s
    p_R(t0) (:func:`~lapwrench.rcm.geometry.initial_rcm_point`) with MuJoCo's lap_E pose at q0."""
    p_e, R = flange_pose_at(cfg.kind, cfg.scope, tuple(cfg.initial_configuration().tolist()))
    d_z, P = scope_axis(R)
    return initial_rcm_point(ScopeAxis(p_e, d_z, P), cfg.scope.length, cfg.rcm_lambda0)


def build_scene(config: SceneConfig | None = None) -> Scene:
    """Compile the complete world (arm + scope + phantom + instruments) for ``config``."""
    cfg = config or SceneConfig()
    q0 = cfg.initial_configuration()
    incision = incision_position_for(cfg)
    spec = build_arm_spec(cfg.kind, cfg.scope, armature=cfg.armature)
    spec.modelname = f"lapwrench_{cfg.kind}"
    add_materials(spec)
    add_link_capsules(spec, cfg.kind)
    dress_scope(spec, cfg.scope, cfg.camera)
    housing = add_phantom(spec, cfg.phantom, incision)
    add_incision(spec, housing, cfg, _scope_quat_at(cfg))
    add_instruments(spec, incision, cfg.phantom)

    opt = spec.option
    opt.timestep = cfg.timestep
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.iterations = 50
    opt.tolerance = 1e-10

    add_joint_servos(spec, cfg.kind)

    spec.worldbody.add_light(
        name="room",
        pos=[incision[0] - 0.3, incision[1], 2.0],
        dir=[0.15, 0, -1],
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        diffuse=[0.55, 0.55, 0.55],
        castshadow=False,
    )
    add_overview_camera(spec, incision)
    configure_rendering(spec, cfg.camera, incision)

    model = spec.compile()
    return Scene(
        spec=spec,
        model=model,
        config=cfg,
        q0=q0,
        incision_position=incision,
        arm_joint_names=arm_spec(cfg.kind).joint_names,
    )
