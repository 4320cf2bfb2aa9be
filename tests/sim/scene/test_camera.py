"""The laparoscope camera: pinhole projection and the paper's intrinsics."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from helpers import make_renderable_world

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.camera import CameraIntrinsics
from lapwrench.sim.world import SimWorld


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


def test_pinhole_projection_helper() -> None:
    cam = CameraIntrinsics()
    np.testing.assert_allclose(cam.project(np.array([0.0, 0.0, 0.1])), [312.22, 243.39])
    uv = cam.project(np.array([[0.01, -0.02, 0.1]]))
    np.testing.assert_allclose(uv, [[312.22 + 50.657, 243.39 - 101.344]])


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
