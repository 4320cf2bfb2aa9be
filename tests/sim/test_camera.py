"""The closed loop's camera: frames drawn in a child process while the loop steps on are the frames, the
capture times, the modes and the detections of frames drawn in the loop's own process."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import make_renderable_world

from lapwrench.config import load
from lapwrench.sim.camera import SimCamera, frame_hold
from lapwrench.sim.loop import ClosedLoop
from lapwrench.sim.scene.build import Scene
from lapwrench.sim.world import CONTROL_DT

TICKS = 130  # frames captured at 0, 40, 80 and 120 ms
Frames = list[tuple[float, str, np.ndarray]]  # (capture time, mode, image) as the frame callback got them


def closed_run(detector: str, background: bool) -> tuple[Frames, np.ndarray, list[np.ndarray]]:
    """Frames handed to the callback, the commands and the detector's points of a short scripted run."""
    frames: Frames = []
    loop = ClosedLoop(load(), seed=0, detector=detector, render_in_background=background,
                      on_frame=lambda f, t, mode: frames.append((t, mode, f.copy())))
    w = loop.world
    rest = w.incision_rest_position()
    q_refs, points = [], []
    try:
        for k in range(TICKS):
            w.set_instrument_tip(0, rest + np.array([0.01 - 1e-4 * k, 0.0, -0.145]))
            w.set_hand_wrench(force=np.array([2.0 * np.sin(k * 0.05), 1.0, 0.0]))
            q_refs.append(loop.step(30.0).q_ref.copy())
            assert loop.detection is not None
            points.append(loop.detection.observation(loop.t).points.copy())
    finally:
        loop.close()  # hands over the frame still being drawn
    return frames, np.array(q_refs), points


@pytest.mark.slow  # four closed loops and two render processes: minutes on a busy 2-core machine
@pytest.mark.parametrize("detector", ["classical", "projected"])
def test_background_frames_are_the_loops_own_frames_with_the_same_detections(detector: str) -> None:
    make_renderable_world().close()  # skips without headless GL
    frames, q_refs, points = closed_run(detector, background=False)
    frames_bg, q_refs_bg, points_bg = closed_run(detector, background=True)
    assert [t for t, _, _ in frames] == pytest.approx([0.0, 0.04, 0.08, 0.12])
    assert [(t, mode) for t, mode, _ in frames_bg] == [(t, mode) for t, mode, _ in frames]
    for (_, _, a), (_, _, b) in zip(frames, frames_bg, strict=True):
        np.testing.assert_array_equal(b, a)
    np.testing.assert_array_equal(q_refs_bg, q_refs)
    assert len(points_bg) == len(points)
    for a, b in zip(points, points_bg, strict=True):
        np.testing.assert_array_equal(b, a)


def test_a_camera_renders_a_begun_frame_at_once_without_background(panda_scene: Scene) -> None:
    w = make_renderable_world(panda_scene)
    cam = SimCamera(w)
    try:
        with pytest.raises(RuntimeError, match="no frame begun"):
            cam.finish()
        assert cam.begin(0.0)
        assert not cam.begin(0.02)  # 25 fps: the next frame is due at 40 ms
        np.testing.assert_array_equal(cam.finish(), w.render())
        assert cam.stamp == 0.0
    finally:
        cam.close()
        w.close()


def test_frames_are_held_at_most_until_the_next_frame_and_the_detection_is_due() -> None:
    assert frame_hold(25.0, 0.04, image_free=False) == pytest.approx(0.04)
    assert frame_hold(25.0, 0.02, image_free=False) == pytest.approx(0.02)
    assert frame_hold(25.0, 0.1, image_free=False) == pytest.approx(0.04)
    assert frame_hold(25.0, 0.0, image_free=True) == pytest.approx(0.04)  # the detector ignores the image
    assert frame_hold(25.0, "measured", image_free=False) == 0.0
    assert frame_hold(25.0, 0.0, image_free=False) < 2.5 * CONTROL_DT  # handed over at once
