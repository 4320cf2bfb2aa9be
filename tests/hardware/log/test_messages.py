"""Foxglove image messages in the run log: JPEG bytes and arrays."""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import (
    RunLogger,
    iter_messages,
)


def test_images_as_jpeg_bytes_and_as_arrays(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    rgb = np.zeros((24, 32, 3), np.uint8)
    rgb[:, :, 0] = 200
    with RunLogger(path) as log:
        log.image(0.0, rgb)
        log.image(0.04, b"\xff\xd8\xff\xe0fake", "jpeg")
    images = [m for _, m in iter_messages(path, [runlog.IMAGE_TOPIC])]
    assert [m["frame_id"] for m in images] == ["lap_C", "lap_C"] and [m["format"] for m in images] == ["jpeg"] * 2
    import cv2

    decoded = cv2.imdecode(np.frombuffer(base64.b64decode(images[0]["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (24, 32, 3) and decoded[..., 2].mean() > 150  # red stays red (RGB in, BGR decoded)
    assert base64.b64decode(images[1]["data"]) == b"\xff\xd8\xff\xe0fake"
