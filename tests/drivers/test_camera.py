"""Camera grabber on a small MJPG video written by the test, plus open/format errors."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import open_fds

from lapwrench.drivers.base import DeviceOpenError, PacketError
from lapwrench.drivers.camera import Camera, CameraFrame, to_rgb

W, H, N_FRAMES, FPS = 64, 48, 12, 25.0


def wait_until(cond: Callable[[], bool], timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


@pytest.fixture
def video(tmp_path: Path) -> Path:
    """A 12-frame 64x48 MJPG .avi: strong red (BGR (0, 0, 220)), green ramping with the index."""
    path = tmp_path / "lap.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (W, H))
    assert writer.isOpened(), "OpenCV cannot write MJPG AVI"
    for k in range(N_FRAMES):
        img = np.zeros((H, W, 3), np.uint8)
        img[:, :, 2] = 220  # red in BGR
        img[:, :, 1] = k * 20
        writer.write(img)
    writer.release()
    return path


def test_file_frames_are_rgb_uint8_with_increasing_index(video: Path) -> None:
    baseline = threading.active_count()
    cam = Camera(video, pace=False)
    with cam:
        assert threading.active_count() <= baseline + 1
        first = cam.latest()
        assert first is not None  # frame 0 is published by start()
        assert wait_until(lambda: cam.status().finished)
        frames_seen = cam.status().samples
    assert frames_seen == N_FRAMES
    s = cam.latest()
    f: CameraFrame = s.value
    assert f.image.shape == (H, W, 3) and f.image.dtype == np.uint8
    assert not f.image.flags.writeable
    assert f.size == (W, H)
    assert f.index == N_FRAMES - 1
    r, g, b = (float(f.image[..., c].mean()) for c in range(3))
    assert r > 180 and b < 40  # RGB order, not BGR
    assert g == pytest.approx((N_FRAMES - 1) * 20, abs=25)
    assert first.value.index == first.seq - 1  # no frame dropped
    assert s.seq == N_FRAMES
    assert cam.status().malformed == 0
    assert not cam.running
    assert threading.active_count() == baseline


def test_file_is_paced_and_goes_stale_at_end(video: Path) -> None:
    with Camera(video, playback_fps=100.0) as cam:  # paced: 12 frames at 100 fps ~ 0.12 s
        t0 = time.monotonic()
        assert wait_until(lambda: cam.status().finished)
        elapsed = time.monotonic() - t0
        assert elapsed > 0.08
        assert cam.status().samples == N_FRAMES
        time.sleep(0.1)
        assert not cam.fresh(0.05)  # nothing new after the end of the file


def test_loop_keeps_streaming(video: Path) -> None:
    with Camera(video, loop=True, playback_fps=200.0) as cam:
        assert wait_until(lambda: cam.latest().seq > N_FRAMES + 3)
        assert cam.running and not cam.status().finished
        assert cam.fresh(0.5)
        assert cam.status().rate_hz > 50
    assert not cam.running


def test_stop_while_paced_is_prompt(video: Path) -> None:
    Camera(video).start().stop()  # OpenCV's first use may open descriptors it keeps
    fds = open_fds()
    cam = Camera(video, playback_fps=2.0).start()  # 0.5 s between frames
    first = cam.latest()
    assert first is not None and first.value.index == 0  # start() publishes frame 0 itself
    t0 = time.monotonic()
    cam.stop()
    assert time.monotonic() - t0 < 0.5
    assert not cam.running
    assert open_fds() == fds  # the file is released


def test_missing_file_names_path_and_starts_nothing(tmp_path: Path) -> None:
    baseline = threading.active_count()
    missing = tmp_path / "nope.avi"
    cam = Camera(missing)
    with pytest.raises(DeviceOpenError, match=r"nope\.avi"):
        cam.start()
    assert not cam.running and cam.latest() is None
    assert threading.active_count() == baseline


def test_unopenable_file_and_device_index(tmp_path: Path) -> None:
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"this is not a video" * 10)
    with pytest.raises(DeviceOpenError, match=r"junk\.avi"):
        Camera(junk).start()
    with pytest.raises(DeviceOpenError, match="camera device '99'"):
        Camera(99).start()


def test_expected_size_mismatch_fails_at_start(video: Path) -> None:
    with pytest.raises(DeviceOpenError, match="expected 640x480"):
        Camera(video, expected_size=(640, 480)).start()
    with Camera(video, expected_size=(W, H), pace=False) as cam:
        assert wait_until(lambda: cam.status().finished)
        assert cam.status().samples == N_FRAMES


def test_to_rgb_conversions_and_validation() -> None:
    gray = np.full((4, 5), 7, np.uint8)
    out = to_rgb(gray)
    assert out.shape == (4, 5, 3) and (out == 7).all()
    bgra = np.zeros((4, 5, 4), np.uint8)
    bgra[..., 0] = 255  # blue
    assert (to_rgb(bgra)[..., 2] == 255).all()
    with pytest.raises(PacketError, match="dtype"):
        to_rgb(np.zeros((4, 5, 3), np.uint16))
    with pytest.raises(PacketError, match="channels"):
        to_rgb(np.zeros((4, 5, 2), np.uint8))
    with pytest.raises(PacketError):
        to_rgb(None)
    with pytest.raises(PacketError):
        to_rgb(np.zeros((0, 5, 3), np.uint8))
    with pytest.raises(PacketError, match="expected 6x4"):
        to_rgb(np.zeros((4, 5, 3), np.uint8), expected_size=(6, 4))


def test_unreachable_stream_url_fails_fast_naming_url() -> None:
    import socket

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nothing listens there
    url = f"rtsp://127.0.0.1:{port}/lap"
    t0 = time.monotonic()
    with pytest.raises(DeviceOpenError, match=f"camera stream '{url}'"):
        Camera(url, open_timeout_ms=1000).start()
    assert time.monotonic() - t0 < 5.0


def test_a_truncated_video_is_counted_and_reported(tmp_path: Path) -> None:
    """Issue 11: a truncated file used to just end early, with nothing counted or reported."""
    path = tmp_path / "long.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (W, H))
    for k in range(40):
        img = np.zeros((H, W, 3), np.uint8)
        img[:, :, 2], img[:, :, 1] = 220, k * 5
        writer.write(img)
    writer.release()
    data = path.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: int(0.6 * len(data))])  # the container still declares 40 frames
    with Camera(cut, pace=False) as cam:
        assert wait_until(lambda: cam.status().finished)
        st = cam.status()
    assert 0 < st.samples < 40
    assert st.malformed == 1 and st.drops == 40 - st.samples
    assert st.last_error is not None and "of its 40 frames" in st.last_error


def test_a_complete_video_reports_nothing(video: Path) -> None:
    with Camera(video, pace=False) as cam:
        assert wait_until(lambda: cam.status().finished)
        st = cam.status()
    assert st.samples == N_FRAMES and st.malformed == 0 and st.drops == 0
