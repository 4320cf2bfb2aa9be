"""The laparoscope view: annotations, and frames rendered by the child process from the session's state."""

from __future__ import annotations

import time

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.ui.session import Session
from lapwrench.ui.snapshot import Snapshot
from lapwrench.ui.view import LaparoscopeView, annotate, next_due, view_size


def test_view_size_scales_the_camera_image(cfg: Config) -> None:
    assert view_size(cfg, 1.0) == (cfg.camera.width, cfg.camera.height)
    assert view_size(cfg, 0.5) == (320, 240)


def test_annotate_draws_the_deadbands_and_detections_at_the_frames_scale(cfg: Config) -> None:
    frame = np.zeros((240, 320, 3), np.uint8)
    out = annotate(frame, cfg, None)
    assert out is not frame and not frame.any()
    s = 0.5
    u0, v0 = round(cfg.camera.u0 * s), round(cfg.camera.v0 * s)
    r1, r2 = round(cfg.tracking.epsilon1 * s), round(cfg.tracking.epsilon2 * s)
    assert out[v0, u0 + r1].any() and out[v0 - r2, u0].any()  # on the ε1 and ε2 circles
    assert not out[v0, u0].any()  # the centre is clear
    snap = Snapshot(
        t=1.0, mode="tracking", delta=0.0, held=None, alarms=(), body_pos=np.zeros((1, 3)),
        body_quat=np.zeros((1, 4)), hand_point=np.zeros(3), hand_force=np.zeros(3), cue_forces={},
        trocar_force=np.zeros(3), incision=np.zeros(3), p_R=np.zeros(3), shaft_dir=np.zeros(3), rcm_error_mm=0.0,
        disturbance=False, script=False, pending_config=False,
        detections=(((100.0, 100.0, 140.0, 140.0), (120.0, 120.0)),),
    )
    boxed = annotate(frame, cfg, snap)
    assert (boxed[50, 50:71] == (0, 255, 0)).all()  # the box's top edge, at half scale
    assert (boxed[60, 60] == (255, 0, 0)).all()  # the tracking point


def test_frames_are_due_at_a_fixed_rate_and_a_late_one_restarts_the_count() -> None:
    assert next_due(1.0, 0.04, now=1.01) == pytest.approx(1.04)  # on time: one period later
    assert next_due(1.0, 0.04, now=1.05) == pytest.approx(1.04)  # a little late: due at once, rate kept
    assert next_due(1.0, 0.04, now=1.2) == 1.2  # far behind: from now, no burst of frames


def test_bad_view_settings_are_refused(cfg: Config) -> None:
    session = Session(cfg)
    with pytest.raises(ValueError):
        LaparoscopeView(session, fps=0.0)
    with pytest.raises(ValueError):
        LaparoscopeView(session, scale=2.0)
    session.closed.world.close()


@pytest.mark.slow
def test_frames_come_from_the_render_process_while_the_session_steps(cfg: Config) -> None:
    session = Session(cfg)
    images: list[np.ndarray] = []
    view = LaparoscopeView(session, fps=25.0, scale=0.5, on_image=images.append)
    session.on_tick.append(view.on_tick)
    view.start()
    try:
        end = time.monotonic() + 120.0
        while len(images) < 3 and time.monotonic() < end and view.error is None:
            session.step()
    finally:
        view.stop()
        session.closed.world.close()
    assert view.error is None
    assert len(images) >= 3
    img = images[-1]
    assert img.shape == (240, 320, 3)
    assert img.std() > 10.0  # a textured scene, not a blank frame
