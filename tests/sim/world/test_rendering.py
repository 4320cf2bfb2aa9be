"""Rendering the laparoscope frame."""

from __future__ import annotations

import numpy as np
from helpers import make_renderable_world

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.names import CAMERA_NAME


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
