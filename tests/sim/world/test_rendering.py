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


def test_a_world_drawn_on_one_thread_closes_on_another(panda_scene: Scene) -> None:
    """``ui --foxglove`` draws the live view on the sim thread and closes the world on the main thread
    (Ctrl-C, or a reset from the page): MuJoCo's renderer leaves its GL context current on the thread
    that drew, and freeing it from another thread failed with EGL_BAD_ACCESS, a traceback at exit."""
    import threading

    w = make_renderable_world(panda_scene)
    images: list[np.ndarray] = []
    drawer = threading.Thread(target=lambda: images.append(w.render()))
    drawer.start()
    drawer.join()
    w.close()  # another thread than the one that drew
    assert images[0].shape == (480, 640, 3)
    again = make_renderable_world(panda_scene)  # and this thread can still draw
    try:
        assert again.render().std() > 10.0
    finally:
        again.close()
