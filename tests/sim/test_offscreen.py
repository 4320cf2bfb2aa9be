"""The laparoscope view drawn in a child process is the image SimWorld.render draws at the same state."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import make_renderable_world

from lapwrench.sim.offscreen import OffscreenRenderer
from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.names import CAMERA_NAME
from lapwrench.sim.world import SimulationUnstableError, SimWorld


def test_child_process_frames_are_the_in_process_frames_pixel_for_pixel(panda_scene: Scene) -> None:
    w = make_renderable_world(panda_scene)
    r = OffscreenRenderer(w, CAMERA_NAME)
    try:
        rest = w.incision_rest_position()
        q = w.scene.q0 + np.array([0.01, -0.01, 0.0, 0.01, 0.0, 0.01, 0.1])
        for k in range(3):
            w.set_instrument_tip(0, rest + np.array([0.01 - 0.01 * k, 0.004 * k, -0.145]))
            for _ in range(20):
                w.step(q)
            # set after the tick's mj_forward: render() still draws the poses of that forward, so must the child
            w.set_instrument_tip(1, rest + np.array([-0.02, 0.01 * k, -0.14]))
            assert r.start()
            assert not r.start(), "one frame in flight at a time"
            here = w.render()
            there = r.result()
            assert there.shape == here.shape == (480, 640, 3) and there.dtype == np.uint8
            assert here.std() > 10.0, "frame looks blank"
            np.testing.assert_array_equal(there, here)
    finally:
        r.close()
        w.close()


def test_after_a_failed_tick_there_is_no_state_to_draw_and_nothing_is_sent(panda_scene: Scene) -> None:
    w = SimWorld(panda_scene, max_contact_force=-1.0)  # every tick fails its contact force check
    r = OffscreenRenderer(w, CAMERA_NAME)
    try:
        assert w.render_state() is not None  # after the reset's forward
        with pytest.raises(RuntimeError, match="no frame in flight"):
            r.result()
        with pytest.raises(SimulationUnstableError):
            w.step(w.scene.q0)
        assert w.render_state() is None
        assert not r.start() and not r.in_flight
    finally:
        r.close()
        w.close()


def test_the_laparoscope_view_leaves_out_the_room_it_never_sees(panda_scene: Scene) -> None:
    """The floor and the table lie outside the phantom's closed housing: the laparoscope's view does not
    draw them (nor the arm), and its frames are those drawn with them, pixel for pixel, as the scope moves."""
    import mujoco

    from lapwrench.sim.offscreen import make_renderer, scope_view_option

    w = make_renderable_world(panda_scene)
    m = w.model
    with_room = mujoco.MjvOption()  # a default view: draws the room and the arm too
    r = make_renderer(m, 640, 480)
    try:
        r.update_scene(w.data, camera=CAMERA_NAME, scene_option=scope_view_option())
        drawn = {m.geom(int(r.scene.geoms[i].objid)).name for i in range(r.scene.ngeom)
                 if r.scene.geoms[i].objtype == mujoco.mjtObj.mjOBJ_GEOM}
        assert "tissue" in drawn and not drawn & {"floor", "table"}
        rest = w.incision_rest_position()
        for k in range(4):
            w.set_instrument_tip(0, rest + np.array([0.01 - 0.01 * k, 0.004 * k, -0.145]))
            q = w.scene.q0 + k * np.array([0.01, -0.01, 0.0, 0.01, 0.0, 0.01, 0.3])
            for _ in range(150):
                w.step(q)
            r.update_scene(w.data, camera=CAMERA_NAME, scene_option=with_room)
            assert np.array_equal(w.render(), r.render()), k
    finally:
        r.close()
        w.close()
