"""Rendering of :class:`~lapwrench.sim.world.SimWorld`: camera frames (the laparoscope view by default)
through one offscreen renderer per image size, and freeing their GL contexts.

A mixin: the world creates the renderer table and the laparoscope's visual options at construction.
"""

from __future__ import annotations

import mujoco
import numpy as np

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.names import CAMERA_NAME


class WorldRendering:
    """Camera frames of a :class:`~lapwrench.sim.world.SimWorld`."""

    scene: Scene
    model: mujoco.MjModel
    data: mujoco.MjData
    _renderers: dict[tuple[int, int], mujoco.Renderer]
    _scope_vopt: mujoco.MjvOption

    def close(self) -> None:
        """Free the renderers (GL contexts)."""
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()

    def render(self, camera: str = CAMERA_NAME, width: int | None = None, height: int | None = None) -> np.ndarray:
        """RGB uint8 image (height, width, 3); default: the 640 x 480 laparoscope view."""
        cam = self.scene.config.camera
        w = width or cam.width
        h = height or cam.height
        key = (w, h)
        r = self._renderers.get(key)
        if r is None:
            r = mujoco.Renderer(self.model, height=h, width=w)
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
            self._renderers[key] = r
        # The arm (geom group 1) is never in the laparoscope's view: skip drawing it there.
        r.update_scene(self.data, camera=camera, scene_option=self._scope_vopt if camera == CAMERA_NAME else None)
        return r.render()
