"""The laparoscope view as a video (:mod:`lapwrench.sim.video`): the annotation drawn on each frame, and
MP4s written from synthetic frames and read back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lapwrench.config import Config, load
from lapwrench.sim.video import VideoWriter, annotate_frame

iio = pytest.importorskip("imageio.v3")

H, W = 480, 640  # the shipped camera's image


@pytest.fixture(scope="module")
def cfg() -> Config:
    return load()


def _ring_pixel(cfg: Config, radius: float) -> tuple[int, int]:
    """(row, column) of the pixel ``radius`` px right of the principal point, on the drawn circle."""
    return round(cfg.camera.v0), round(cfg.camera.u0) + int(radius)


def _ring(img: np.ndarray, cfg: Config, radius: float) -> tuple[int, ...]:
    """The brightest pixel within 3 px of the circle's point right of the principal point (the circles
    are anti-aliased: the line is spread over neighbouring pixels)."""
    row, col = _ring_pixel(cfg, radius)
    window = img[row, col - 3 : col + 4].reshape(7, -1).astype(int)
    return tuple(window[np.argmax(window.sum(axis=1))])


def _white(px: tuple[int, ...]) -> bool:
    return min(px) > 150 and max(px) - min(px) <= 1


def _yellow(px: tuple[int, ...]) -> bool:  # (255, 255, 0) as drawn: red and green, no blue
    return px[0] > 150 and px[0] == px[1] and px[2] == 0


# -- annotate_frame --------------------------------------------------------------------------------
def test_the_deadband_circles_and_the_label_are_drawn_on_a_copy(cfg: Config) -> None:
    frame = np.zeros((H, W, 3), np.uint8)
    img = annotate_frame(frame, cfg, "t= 1.00 s  tracking")
    assert not frame.any()  # the caller's frame is untouched
    assert img.shape == frame.shape and img.dtype == np.uint8
    assert _white(_ring(img, cfg, cfg.tracking.epsilon1))  # inner deadband
    assert _yellow(_ring(img, cfg, cfg.tracking.epsilon2))  # outer deadband
    assert not img[round(cfg.camera.v0), round(cfg.camera.u0)].any()  # the centre is left clear
    assert img[:30, :200].any()  # the label, top left


def test_the_circles_follow_the_configured_deadbands(cfg: Config) -> None:
    moved = cfg.replace(tracking={"epsilon1": 30.0, "epsilon2": 120.0})
    img = annotate_frame(np.zeros((H, W, 3), np.uint8), moved, "")
    assert _white(_ring(img, moved, 30.0)) and _yellow(_ring(img, moved, 120.0))
    assert not any(_ring(img, cfg, cfg.tracking.epsilon1))  # nothing at the old radius
    assert not img[:30, :200].any()  # an empty label draws nothing


def test_a_grey_frame_is_annotated_in_grey(cfg: Config) -> None:
    img = annotate_frame(np.zeros((H, W), np.uint8), cfg, "x")
    assert img.shape == (H, W) and _ring(img, cfg, cfg.tracking.epsilon1)[0] > 150


def test_a_frame_smaller_than_the_circles_is_clipped_not_refused(cfg: Config) -> None:
    img = annotate_frame(np.zeros((60, 80, 3), np.uint8), cfg, "small")
    assert img.shape == (60, 80, 3)


@pytest.mark.parametrize(
    "frame",
    [np.zeros((H, W, 3)), np.full((H, W, 3), np.nan, np.float32), np.zeros((H, W, 3), np.int64)],
    ids=["float64", "nan", "int64"],
)
def test_a_frame_that_is_not_8_bit_is_refused_naming_it(cfg: Config, frame: np.ndarray) -> None:
    with pytest.raises(ValueError, match="frame"):
        annotate_frame(frame, cfg, "x")


# -- VideoWriter -------------------------------------------------------------------------------------
def _frames(n: int, h: int = H, w: int = W) -> list[np.ndarray]:
    """``n`` frames, each a flat grey a little brighter than the one before."""
    return [np.full((h, w, 3), 40 + 15 * k, np.uint8) for k in range(n)]


def _write(path: Path, cfg: Config, frames: list[np.ndarray], **kw: float) -> np.ndarray:
    w = VideoWriter(path, cfg, **kw)
    try:
        for k, f in enumerate(frames):
            w.add(f, f"frame {k}")
    finally:
        w.close()
    return iio.imread(path, index=None)


def test_a_short_video_reads_back_frame_for_frame(tmp_path: Path, cfg: Config) -> None:
    path = tmp_path / "view.mp4"
    video = _write(path, cfg, _frames(12))
    assert video.shape == (12, H, W, 3) and video.dtype == np.uint8
    # each frame's background survives the encoder (H.264 is lossy: within a few grey levels)
    background = video[:, H - 20, 20].astype(float).mean(axis=1)
    assert np.allclose(background, [40 + 15 * k for k in range(12)], atol=4)
    # and carries the annotation: the outer deadband's yellow circle on the first frame's grey 40
    row, col = _ring_pixel(cfg, cfg.tracking.epsilon2)
    ring = video[0, row, col - 3 : col + 4].astype(int)
    assert ring[:, 0].max() > 150 and ring[:, 2].max() < ring[:, 0].max() - 60, ring.tolist()
    assert iio.immeta(path)["fps"] == pytest.approx(25.0)


def test_the_frame_rate_is_written(tmp_path: Path, cfg: Config) -> None:
    path = tmp_path / "slow.mp4"
    assert len(_write(path, cfg, _frames(3), fps=10.0)) == 3
    assert iio.immeta(path)["fps"] == pytest.approx(10.0)


def test_a_size_off_the_16_pixel_grid_is_padded_up_to_it(tmp_path: Path, cfg: Config) -> None:
    """H.264 players want multiples of 16: a 100 x 75 view is written as 112 x 80."""
    video = _write(tmp_path / "odd.mp4", cfg, _frames(2, h=75, w=100))
    assert video.shape == (2, 80, 112, 3)


def test_frames_that_change_size_are_refused(tmp_path: Path, cfg: Config) -> None:
    w = VideoWriter(tmp_path / "mixed.mp4", cfg)
    try:
        w.add(_frames(1)[0], "first")
        with pytest.raises(ValueError, match="same size"):
            w.add(_frames(1, h=240, w=320)[0], "second")
    finally:
        w.close()


def test_a_video_closed_without_frames_leaves_no_file(tmp_path: Path, cfg: Config) -> None:
    """The demo links a scenario's MP4 only if it exists: a run that drew nothing links none."""
    VideoWriter(tmp_path / "empty.mp4", cfg).close()
    assert not (tmp_path / "empty.mp4").exists()


def test_a_missing_folder_is_named(tmp_path: Path, cfg: Config) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        VideoWriter(tmp_path / "nowhere" / "view.mp4", cfg)


@pytest.mark.parametrize("fps", [math.nan, -5.0, 0.0, math.inf])
def test_a_bad_frame_rate_is_refused_when_the_writer_is_made(tmp_path: Path, cfg: Config, fps: float) -> None:
    with pytest.raises(ValueError, match="fps"):
        VideoWriter(tmp_path / "bad.mp4", cfg, fps=fps)
