"""The laparoscope view as a video: frames annotated with the tracking deadbands and a label.

Below both the scenarios (which write the video while they run) and the report (whose snapshot
strip annotates frames the same way).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lapwrench.config import Config


def annotate_frame(frame: np.ndarray, cfg: Config, label: str) -> np.ndarray:
    import cv2

    if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim not in (2, 3):
        got = f"{frame.dtype} {frame.shape}" if isinstance(frame, np.ndarray) else type(frame).__name__
        raise ValueError(f"video frame must be an 8-bit image (uint8, H x W or H x W x C), got {got}")
    img = np.ascontiguousarray(frame.copy())
    c = (round(cfg.camera.u0), round(cfg.camera.v0))
    cv2.circle(img, c, int(cfg.tracking.epsilon1), (255, 255, 255), 1, cv2.LINE_AA)
    cv2.circle(img, c, int(cfg.tracking.epsilon2), (255, 255, 0), 1, cv2.LINE_AA)
    cv2.putText(img, label, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2, cv2.LINE_AA)
    return img


class VideoWriter:
    """MP4 of the laparoscope view (H.264 through imageio-ffmpeg), frames annotated as they come."""

    def __init__(self, path: Path, cfg: Config, fps: float = 25.0) -> None:
        import imageio.v2 as imageio

        if isinstance(fps, bool) or not isinstance(fps, int | float) or not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"video fps must be a positive number, got {fps!r}")
        self.path = path
        self.cfg = cfg
        # x264's veryfast preset: 8 ms of CPU a 640x480 frame instead of 18 ms with the default (medium),
        # for a file no larger (2026-12-02); the encoder shares the cores with the simulation
        self._w = imageio.get_writer(path, fps=fps, codec="libx264", quality=6, macro_block_size=16,
                                     ffmpeg_params=["-preset", "veryfast"])

    def add(self, frame: np.ndarray, label: str) -> None:
        self._w.append_data(annotate_frame(frame, self.cfg, label))

    def close(self) -> None:
        self._w.close()
