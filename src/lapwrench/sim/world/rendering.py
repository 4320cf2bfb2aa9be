"""Rendering of :class:`~lapwrench.sim.world.SimWorld`: camera frames (the laparoscope view by default)
through one offscreen renderer per image size, and freeing their GL contexts.

A mixin: the world creates the renderer table and the laparoscope's visual options at construction.
"""

from __future__ import annotations

import mujoco
import numpy as np

from lapwrench.sim.offscreen import make_renderer, release_context
from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.names import CAMERA_NAME


class WorldRendering:
    """Camera frames of a :class:`~lapwrench.sim.world.SimWorld`."""

    scene: Scene
    model: mujoco.MjModel
    data: mujoco.MjData
    _renderers: dict[tuple[int, int], mujoco.Renderer]
    _scope_vopt: mujoco.MjvOption
    _fwd_valid: bool
    _fwd: np.ndarray

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
            r = self._renderers[key] = make_renderer(self.model, w, h)
        r.update_scene(self.data, camera=camera, scene_option=self._scope_vopt if camera == CAMERA_NAME else None)
        try:
            return r.render()
        finally:
            release_context()  # any thread may draw or close the world next

    def render_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Copies of (qpos, mocap_pos, mocap_quat) at the last ``mj_forward``: the state :meth:`render`
        draws (its poses are that forward's, whatever was set since), from which a renderer of its own
        draws the same image (:mod:`lapwrench.sim.offscreen`). None while no forward is known to
        hold (inside a tick, or after a failed one)."""
        if not self._fwd_valid:
            return None
        m, fwd = self.model, self._fwd
        nq, nv, nm = m.nq, m.nv, m.nmocap
        k = nq + nv
        return (fwd[:nq].copy(), fwd[k : k + 3 * nm].reshape(nm, 3).copy(),
                fwd[k + 3 * nm : k + 7 * nm].reshape(nm, 4).copy())

