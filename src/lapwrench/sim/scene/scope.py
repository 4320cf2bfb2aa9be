"""The laparoscope dressed for the simulation: visuals, tip light, frame sites and the handle F/T sensor.

The scope's links come with the arm (:mod:`lapwrench.sim.scene.arm`); this module colours them,
puts the camera (:func:`lapwrench.sim.scene.camera.add_scope_camera`) and a spot light at the tip,
and adds the force/torque sensor between the hand grip (lap_H) and the scope.
"""

from __future__ import annotations

import mujoco

from lapwrench.robot.description import FRAME_C, FRAME_E, FRAME_H, ScopeGeometry
from lapwrench.sim.scene.camera import CameraIntrinsics, add_scope_camera
from lapwrench.sim.scene.names import FT_FORCE_SENSOR, FT_TORQUE_SENSOR


def dress_scope(spec: mujoco.MjSpec, scope: ScopeGeometry, cam: CameraIntrinsics) -> None:
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
    add_scope_camera(tip, cam)
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
