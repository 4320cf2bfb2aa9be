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


def test_a_camera_that_does_not_draw_keeps_the_frame_clock_of_one_that_does(panda_scene: Scene) -> None:
    w = make_renderable_world(panda_scene)
    drawing, clock_only = SimCamera(w), SimCamera(w, draw=False, background=True)
    try:
        assert clock_only.offscreen is None  # nothing to draw: no render process either
        ticks = [k * CONTROL_DT for k in range(1000)]
        assert [clock_only.capture(t) for t in ticks] == [drawing.capture(t) for t in ticks]
        assert sum(clock_only.capture(1.0 + t) for t in ticks) == 25
        assert clock_only.frame is not None and clock_only.frame.size == 0 and clock_only.stamp > 1.9
        assert drawing.frame is not None and drawing.frame.size > 0
    finally:
        drawing.close()
        clock_only.close()
        w.close()


def projected_run(on_frame: bool) -> tuple[list[float], list[np.ndarray], np.ndarray, bool]:
    """Frame times handed to the callback, the detections' points, the commands, and whether the camera draws."""
    seen: list[float] = []
    loop = ClosedLoop(load(), seed=0, detector="projected",
                      on_frame=(lambda f, t, mode: seen.append(t)) if on_frame else None)
    rest = loop.world.incision_rest_position()
    points, q_refs = [], []
    try:
        assert loop.camera is not None and loop.detection is not None
        for k in range(90):
            loop.world.set_instrument_tip(0, rest + np.array([0.01 - 1e-4 * k, 0.0, -0.145]))
            q_refs.append(loop.step(0.0).q_ref.copy())
            points.append(loop.detection.observation(loop.t).points.copy())
        return seen, points, np.array(q_refs), loop.camera.draws
    finally:
        loop.close()


def test_the_projected_detector_alone_draws_no_frames_and_detects_the_same() -> None:
    """Without anyone taking the images (no frame callback, no live telemetry) a loop with the projected
    detector draws nothing; its detections, at the same capture times, steer the same commands."""
    make_renderable_world().close()  # skips without headless GL
    seen, points, q_refs, draws = projected_run(on_frame=True)
    seen_none, points_none, q_refs_none, draws_none = projected_run(on_frame=False)
    assert draws and not draws_none
    assert seen == pytest.approx([0.0, 0.04, 0.08]) and seen_none == []
    assert len(points_none) == len(points) and len(points[-1]) > 0
    for a, b in zip(points, points_none, strict=True):
        np.testing.assert_array_equal(b, a)
    np.testing.assert_array_equal(q_refs_none, q_refs)
