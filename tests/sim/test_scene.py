"""Scene geometry: default pose, incision placement, camera intrinsics, rendering."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from helpers import make_renderable_world

from lapwrench.sim.scene.arm import default_initial_configuration
from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.camera import CameraIntrinsics
from lapwrench.sim.scene.config import PhantomConfig, SceneConfig
from lapwrench.sim.scene.names import CAMERA_NAME, INSTRUMENT_BODIES
from lapwrench.sim.world import SimWorld


@pytest.mark.parametrize("kind", ["panda", "fr3"])
def test_default_pose_points_into_incision(kind: str) -> None:
    scene = build_scene(SceneConfig(kind=kind))
    m = scene.model
    q0 = default_initial_configuration(kind)
    np.testing.assert_array_equal(scene.q0, q0)
    lo = m.jnt_range[[m.joint(n).id for n in scene.arm_joint_names], 0]
    hi = m.jnt_range[[m.joint(n).id for n in scene.arm_joint_names], 1]
    assert np.all(q0 - lo > 0.5) and np.all(hi - q0 > 0.5), "q0 must sit well inside the joint limits"
    w = SimWorld(scene)
    p_e, d_z = w.shaft_axis()
    assert d_z[2] < -0.99, "the scope points down into the abdomen"
    np.testing.assert_allclose(scene.incision_position, p_e + 0.8 * 0.29 * d_z, atol=1e-9)
    np.testing.assert_allclose(w.incision_position(), scene.incision_position, atol=1e-9)
    assert w.rcm_error() < 1e-9
    assert w.insertion_depth() == pytest.approx(0.232, abs=1e-9)
    assert np.linalg.norm(w.contact_force()) < 1e-9
    # Nothing collides; the trocar weld is the only robot-phantom interaction.
    assert m.npair == 0 and m.neq == 1
    assert np.all(m.geom_contype == 0) and np.all(m.geom_conaffinity == 0)
    for b in INSTRUMENT_BODIES:
        assert m.body_mocapid[m.body(b).id] >= 0


def test_invalid_configs_are_rejected() -> None:
    with pytest.raises(ValueError, match="timestep"):
        SceneConfig(timestep=0.0007)
    with pytest.raises(ValueError, match="unknown robot"):
        SceneConfig(kind="ur5")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="wall_stiffness"):
        PhantomConfig(wall_stiffness=-1.0)
    with pytest.raises(ValueError, match="rcm_lambda0"):
        SceneConfig(rcm_lambda0=1.2)


def test_pinhole_projection_helper() -> None:
    cam = CameraIntrinsics()
    np.testing.assert_allclose(cam.project(np.array([0.0, 0.0, 0.1])), [312.22, 243.39])
    uv = cam.project(np.array([[0.01, -0.02, 0.1]]))
    np.testing.assert_allclose(uv, [[312.22 + 50.657, 243.39 - 101.344]])


def _probe_scene(scene: Scene, points_c: np.ndarray) -> tuple[Scene, list[int]]:
    """Copy of ``scene`` with small green spheres at camera-frame points (q0 pose)."""
    spec = scene.spec.copy()
    w = SimWorld(scene)
    p, R = w.frame_pose("lap_C")
    for k, pc in enumerate(points_c):
        spec.worldbody.add_geom(
            name=f"probe{k}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[0.0008, 0, 0],
            pos=list(p + R @ pc),
            rgba=[0, 1, 0, 1],
            contype=0,
            conaffinity=0,
        )
    model = spec.compile()
    ids = [model.geom(f"probe{k}").id for k in range(len(points_c))]
    return dataclasses.replace(scene, spec=spec, model=model), ids


def test_camera_projects_points_to_paper_intrinsics(panda_scene: Scene) -> None:
    """A sphere rendered by the tip camera lands on the pixel K [x/z, y/z, 1] predicts (OpenCV)."""
    points_c = np.array([[0.0, 0.0, 0.06], [0.02, 0.01, 0.07], [-0.025, -0.015, 0.06], [0.03, -0.018, 0.05]])
    scene, ids = _probe_scene(panda_scene, points_c)
    w = make_renderable_world(scene)
    expected = scene.config.camera.project(points_c)
    try:
        for k in range(len(points_c)):
            for j, gid in enumerate(ids):
                w.model.geom_rgba[gid, 3] = 1.0 if j == k else 0.0
            img = w.render().astype(int)
            mask = (img[..., 1] > img[..., 0] + 50) & (img[..., 1] > img[..., 2] + 50)
            assert mask.sum() > 30, f"probe {k} not visible"
            vs, us = np.nonzero(mask)
            assert abs(us.mean() - expected[k, 0]) < 1.0 and abs(vs.mean() - expected[k, 1]) < 1.0, (
                f"probe {k}: rendered ({us.mean():.2f}, {vs.mean():.2f}) vs pinhole {expected[k]}"
            )
        # And the world's helper agrees with the camera pose it renders from.
        uv, z = w.project_to_image(w.frame_pose("lap_C")[0] + w.frame_pose("lap_C")[1] @ points_c[1])
        np.testing.assert_allclose(uv, expected[1], atol=1e-9)
        assert z == pytest.approx(0.07)
    finally:
        w.close()


def test_render_laparoscope_frame(panda_scene: Scene) -> None:
    w = make_renderable_world(panda_scene)
    try:
        img = w.render()
        assert img.shape == (480, 640, 3) and img.dtype == np.uint8
        assert img.std() > 10.0, "frame looks blank"
        assert img.mean() > 30.0, "frame too dark"
        img2 = w.render()  # the renderer is reused
        np.testing.assert_array_equal(img, img2)
        over = w.render("overview", 320, 240)
        assert over.shape == (240, 320, 3) and over.std() > 10.0
        assert panda_scene.model.camera(CAMERA_NAME).id >= 0
    finally:
        w.close()
