"""lapwrench.sim.scene.scope: the dressed laparoscope: no contacts of its own, the camera and light at
the tip looking along the shaft, and the handle F/T sensor between the hand grip and the scope."""

from __future__ import annotations

import mujoco
import numpy as np

from lapwrench.robot.description import FRAME_C, FRAME_H
from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.names import CAMERA_NAME, FT_FORCE_SENSOR, FT_TORQUE_SENSOR


def test_the_scope_touches_nothing(panda_scene: Scene) -> None:
    m = panda_scene.model
    for body in ("lap_shaft", "lap_handle"):
        geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(body).id]
        assert geoms and all(m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0 for g in geoms), body
    shaft = next(g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body("lap_shaft").id)
    assert m.material(m.geom_matid[shaft]).name == "metal"


def test_the_camera_and_the_light_look_along_the_shaft_from_the_tip(panda_scene: Scene) -> None:
    m = panda_scene.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_camlight(m, d)
    cam, tip = m.camera(CAMERA_NAME).id, m.body(FRAME_C).id
    assert m.cam_bodyid[cam] == tip
    view = -d.cam_xmat[cam].reshape(3, 3)[:, 2]  # a MuJoCo camera looks along its -z
    np.testing.assert_allclose(view, d.xmat[tip].reshape(3, 3)[:, 2], atol=1e-9)  # {C}'s +z: down the shaft
    light = m.light("scope_light").id
    assert m.light_bodyid[light] == tip and m.light_type[light] == mujoco.mjtLightType.mjLIGHT_SPOT
    c = panda_scene.config.camera
    assert tuple(m.cam_resolution[cam]) == (c.width, c.height)


def test_the_handle_ft_sensor_sits_at_the_hand_grip(panda_scene: Scene) -> None:
    m = panda_scene.model
    site = m.site("lap_H_site").id
    assert m.site_bodyid[site] == m.body(FRAME_H).id
    for name, kind in ((FT_FORCE_SENSOR, mujoco.mjtSensor.mjSENS_FORCE),
                       (FT_TORQUE_SENSOR, mujoco.mjtSensor.mjSENS_TORQUE)):
        s = m.sensor(name)
        assert s.type[0] == kind and s.objid[0] == site and s.dim[0] == 3
