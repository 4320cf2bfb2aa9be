"""Laparoscope camera through OpenCV ``VideoCapture``: a device index, a video file or a stream URL.

A grabber thread reads frames as they come (a device or stream paces itself; a file is paced at
its own frame rate by default, so a recorded video behaves like the 25 fps laparoscope of the
paper, Sec. IV) and publishes :class:`CameraFrame` values into a latest-value buffer. The control
loop and the detector read only the newest frame; older frames are overwritten, never queued, so a
slow consumer never causes latency to build up.

Checks, in order, all in ``start()`` before any thread runs:

1. a file path must exist (error names the path);
2. ``VideoCapture`` must open (error names the index/path/URL);
3. the first frame must be readable and valid: 8-bit, 1/3/4 channels, optionally of the expected
   size. It is converted to RGB and published as frame 0.

Later frames failing validation raise :class:`~lapwrench.drivers.base.PacketError` in the grabber
(counted in ``status().malformed``, frame dropped); read failures of a device or stream are counted
as I/O errors and retried; the end of a file ends the thread (``status().finished``) unless
``loop=True``. A file that ends before the frame count its container declares (truncated or
corrupt) is counted: one malformed frame with the numbers in ``last_error``, the missing frames as
drops.

Frames are ``uint8`` arrays of shape (H, W, 3) in **RGB** order (OpenCV delivers BGR; we convert),
marked read-only. The sample timestamp is the host ``time.monotonic()`` right after the grab.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from lapwrench.drivers.base import DeviceOpenError, EndOfStream, PacketError, StreamingSource

__all__ = ["Camera", "CameraFrame", "to_rgb"]


@dataclass(frozen=True, slots=True)
class CameraFrame:
    """One camera frame.

    Attributes:
        image: (H, W, 3) ``uint8`` RGB, read-only.
        index: 0-based index of the frame since ``start()`` (counts every grabbed frame, so a gap
            means frames were dropped as malformed).
        pos_ms: Position in the source in ms as reported by OpenCV (meaningful for files), or None.
    """

    image: NDArray[np.uint8]
    index: int
    pos_ms: float | None = None

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


def to_rgb(frame: object, expected_size: tuple[int, int] | None = None) -> NDArray[np.uint8]:
    """Validate an OpenCV frame and return a new contiguous (H, W, 3) uint8 RGB array.

    Accepts 8-bit gray (H, W) / (H, W, 1), BGR (H, W, 3) and BGRA (H, W, 4).

    Raises:
        PacketError: not an array, wrong dtype, wrong channel count, empty, or not of
            ``expected_size`` ``(width, height)``.
    """
    if not isinstance(frame, np.ndarray):
        raise PacketError(f"frame is {type(frame).__name__}, not an image array")
    if frame.dtype != np.uint8:
        raise PacketError(f"frame dtype {frame.dtype}, expected uint8")
    if frame.ndim not in (2, 3) or frame.shape[0] == 0 or frame.shape[1] == 0:
        raise PacketError(f"frame shape {frame.shape} is not an image")
    channels = 1 if frame.ndim == 2 else frame.shape[2]
    if channels == 1:
        rgb = cv2.cvtColor(frame.reshape(frame.shape[:2]), cv2.COLOR_GRAY2RGB)
    elif channels == 3:
        rgb = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
    elif channels == 4:
        rgb = cv2.cvtColor(frame, cv2.COLOR_BGRA2RGB)
    else:
        raise PacketError(f"frame has {channels} channels, expected 1, 3 or 4")
    if expected_size is not None:
        w, h = expected_size
        if rgb.shape[1] != w or rgb.shape[0] != h:
            raise PacketError(f"frame size {rgb.shape[1]}x{rgb.shape[0]}, expected {w}x{h}")
    return np.ascontiguousarray(rgb)


def _describe(source: int | str | os.PathLike[str]) -> tuple[str, str]:
    """Classify ``source`` as ('device'|'stream'|'file', normalised text)."""
    if isinstance(source, int):
        return "device", str(source)
    text = os.fspath(source)
    if text.isdigit():
        return "device", text
    if "://" in text:
        return "stream", text
    return "file", text


class Camera(StreamingSource[CameraFrame]):
    """Background frame grabber around ``cv2.VideoCapture``.

    Args:
        source: Device index (``0`` or ``"0"``), video file path, or stream URL
            (``rtsp://``, ``http://``...; ``://`` marks a URL).
        name: Source name (default ``"camera:<source>"``).
        api_preference: OpenCV backend (``cv2.CAP_V4L2``, ``cv2.CAP_FFMPEG``...; default any).
        width, height, fps: Requested device settings (devices only; the driver may ignore them).
        expected_size: ``(width, height)`` every frame must have; mismatches are rejected.
        loop: Rewind a file at its end instead of finishing.
        pace: Deliver file frames at the file's frame rate (default: True for files, False
            otherwise). Ignored for devices and streams, which pace themselves.
        playback_fps: Override the pacing rate of a file (default: the file's FPS, or 25).
        open_timeout_ms: Open/read timeout for streams (FFmpeg backend), so an unreachable URL
            fails in bounded time.
        expected_rate_hz: Nominal frame rate for the ``late`` counter (default: the pacing rate
            for files, ``fps`` for devices).
    """

    def __init__(
        self,
        source: int | str | os.PathLike[str],
        *,
        name: str | None = None,
        api_preference: int = cv2.CAP_ANY,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
        expected_size: tuple[int, int] | None = None,
        loop: bool = False,
        pace: bool | None = None,
        playback_fps: float | None = None,
        open_timeout_ms: int = 5000,
        expected_rate_hz: float | None = None,
    ) -> None:
        self.kind, self.source_text = _describe(source)
        self.source = source
        super().__init__(
            name or f"camera:{self.source_text}",
            expected_rate_hz=expected_rate_hz or (playback_fps if self.kind == "file" else fps),
        )
        self.api_preference = api_preference
        self.width, self.height, self.fps = width, height, fps
        self.expected_size = expected_size
        self.loop = loop
        self.pace = (self.kind == "file") if pace is None else (pace and self.kind == "file")
        self.playback_fps = playback_fps
        self.open_timeout_ms = open_timeout_ms
        self._cap: cv2.VideoCapture | None = None
        self._index = 0
        self._pass_start = 0
        self._period = 0.0
        self._next_due = 0.0

    @property
    def device(self) -> str:
        """Device description used in error messages."""
        return f"camera {self.kind} {self.source_text!r}"

    # ----------------------------------------------------------------- open / close
    def _make_capture(self) -> cv2.VideoCapture:
        if self.kind == "device":
            cap = cv2.VideoCapture(int(self.source_text), self.api_preference)
            for prop, value in (
                (cv2.CAP_PROP_FRAME_WIDTH, self.width),
                (cv2.CAP_PROP_FRAME_HEIGHT, self.height),
                (cv2.CAP_PROP_FPS, self.fps),
            ):
                if value is not None and cap.isOpened():
                    cap.set(prop, float(value))
            return cap
        if self.kind == "stream":
            params = [
                cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
                self.open_timeout_ms,
                cv2.CAP_PROP_READ_TIMEOUT_MSEC,
                self.open_timeout_ms,
            ]
            return cv2.VideoCapture(self.source_text, self.api_preference, params)
        return cv2.VideoCapture(self.source_text, self.api_preference)

    def _open(self) -> None:
        if self.kind == "file" and not Path(self.source_text).is_file():
            raise DeviceOpenError(self.device, "no such file")
        cap = self._make_capture()
        if not cap.isOpened():
            cap.release()
            raise DeviceOpenError(
                self.device,
                "OpenCV VideoCapture could not open it (check the index/path/URL, permissions, "
                "and that no other process holds the device)",
            )
        ok, frame = cap.read()
        if not ok:
            cap.release()
            raise DeviceOpenError(self.device, "opened, but no frame could be read")
        try:
            rgb = to_rgb(frame, self.expected_size)
        except PacketError as exc:
            cap.release()
            raise DeviceOpenError(self.device, f"unsupported frame format: {exc}") from exc
        self._cap = cap
        file_fps = cap.get(cv2.CAP_PROP_FPS) if self.kind == "file" else 0.0
        rate = self.playback_fps or (file_fps if 0 < file_fps < 1000 else 25.0)
        self._period = 1.0 / rate if self.pace else 0.0
        if self.pace and self.rate.expected_rate_hz is None:
            self.rate.expected_rate_hz = rate
        self._index = 0
        self._pass_start = 0
        now = time.monotonic()
        self._publish_frame(rgb, now)
        self._next_due = now + self._period

    def _close(self) -> None:
        cap, self._cap = self._cap, None
        if cap is not None:
            cap.release()

    # ----------------------------------------------------------------- grabbing
    def _publish_frame(self, rgb: NDArray[np.uint8], timestamp: float) -> None:
        rgb.flags.writeable = False
        pos = self._cap.get(cv2.CAP_PROP_POS_MSEC) if (self._cap is not None and self.kind == "file") else None
        self._publish(CameraFrame(rgb, self._index, pos), timestamp)
        self._index += 1

    def _rewind(self, cap: cv2.VideoCapture) -> None:
        if not cap.set(cv2.CAP_PROP_POS_FRAMES, 0):  # backend cannot seek: reopen the file
            cap.release()
            self._cap = cap = cv2.VideoCapture(self.source_text, self.api_preference)
            if not cap.isOpened():
                raise OSError(f"{self.device}: could not reopen to loop")

    def _check_file_end(self, cap: cv2.VideoCapture) -> None:
        """At the end of a file: fewer frames than its container declares is a truncated or corrupt
        file, counted (malformed, and the missing frames as drops) and reported in ``last_error``."""
        declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        got = self._index - self._pass_start
        if declared > 0 and got < declared:
            self.rate.add_drops(declared - got)
            self._record_malformed(
                PacketError(f"{self.device}: the file ended after {got} of its {declared} frames (truncated, corrupt)")
            )

    def _read_once(self) -> None:
        cap = self._cap
        if cap is None:
            raise RuntimeError("capture released")
        if self._period > 0:
            delay = self._next_due - time.monotonic()
            if delay > 0 and self._stop_event.wait(delay):
                return
            self._next_due = max(self._next_due + self._period, time.monotonic() - self._period)
        ok, frame = cap.read()
        now = time.monotonic()
        if not ok:
            if self.kind == "file":
                self._check_file_end(cap)
                if not self.loop:
                    raise EndOfStream
                self._rewind(cap)
                self._pass_start = self._index
                return
            raise OSError(f"{self.device}: frame grab failed")
        try:
            rgb = to_rgb(frame, self.expected_size)
        except PacketError:
            self._index += 1  # keep the gap visible in CameraFrame.index
            raise
        self._publish_frame(rgb, now)
