"""MuJoCo world for the laparoscope-holding robot, built from the shared robot description.

One module per part of the world; this package re-exports their public names, so
``from lapwrench.sim.scene import build_scene`` keeps working (new code may import from the module):

- :mod:`~lapwrench.sim.scene.names`: names of the bodies, joints, sites, sensors and cameras.
- :mod:`~lapwrench.sim.scene.arm`: the arm and the scope's links from ``build_urdf``, torque limits,
  default q0, joint servos.
- :mod:`~lapwrench.sim.scene.camera`: camera intrinsics, the tip and overview cameras, render settings.
- :mod:`~lapwrench.sim.scene.config`: :class:`PhantomConfig` and :class:`SceneConfig`.
- :mod:`~lapwrench.sim.scene.scope`: the laparoscope's visuals, tip light, sites and handle F/T sensor.
- :mod:`~lapwrench.sim.scene.materials`: textures and materials.
- :mod:`~lapwrench.sim.scene.phantom`: the abdominal phantom (housing, wall, ports, tissue, organ, ...).
- :mod:`~lapwrench.sim.scene.trocar`: the elastic incision and the trocar welded to the shaft.
- :mod:`~lapwrench.sim.scene.instruments`: the two mocap instruments and their pose through a port.
- :mod:`~lapwrench.sim.scene.build`: :func:`build_scene` assembles and compiles the world.

Base frame = MuJoCo world frame (the arm's root link sits at the origin). Nothing collides
(contype = conaffinity = 0 everywhere): the trocar constraint is the only interaction between robot
and phantom; arm self-collision is not simulated.
"""

from __future__ import annotations

from lapwrench.sim.scene.arm import TAU_MAX, build_arm_spec, default_initial_configuration
from lapwrench.sim.scene.build import Scene, build_scene, incision_position_for
from lapwrench.sim.scene.camera import CameraIntrinsics
from lapwrench.sim.scene.config import PhantomConfig, SceneConfig
from lapwrench.sim.scene.instruments import instrument_pose_through_port
from lapwrench.sim.scene.names import (
    CAMERA_NAME,
    FT_FORCE_SENSOR,
    FT_TORQUE_SENSOR,
    GAUZE_BODIES,
    HANDLE_BODY,
    HOUSING_BODY,
    HOUSING_JOINTS,
    INCISION_BODY,
    INCISION_JOINTS,
    INSTRUMENT_BODIES,
    INSTRUMENT_TIP_SITES,
    NEEDLE_BODY,
    ORGAN_BODY,
    OVERVIEW_CAMERA_NAME,
    PORT_SITES,
    RING_GEOM_PREFIX,
    SLEEVE_BODY,
    TROCAR_BODY,
    TROCAR_WELD,
)

__all__ = [
    "CAMERA_NAME",
    "FT_FORCE_SENSOR",
    "FT_TORQUE_SENSOR",
    "GAUZE_BODIES",
    "HANDLE_BODY",
    "HOUSING_BODY",
    "HOUSING_JOINTS",
    "INCISION_BODY",
    "INCISION_JOINTS",
    "INSTRUMENT_BODIES",
    "INSTRUMENT_TIP_SITES",
    "NEEDLE_BODY",
    "ORGAN_BODY",
    "OVERVIEW_CAMERA_NAME",
    "PORT_SITES",
    "RING_GEOM_PREFIX",
    "SLEEVE_BODY",
    "TAU_MAX",
    "TROCAR_BODY",
    "TROCAR_WELD",
    "CameraIntrinsics",
    "PhantomConfig",
    "Scene",
    "SceneConfig",
    "build_arm_spec",
    "build_scene",
    "default_initial_configuration",
    "incision_position_for",
    "instrument_pose_through_port",
]
