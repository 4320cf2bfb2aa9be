"""Live telemetry: the log's own channels, streamed to Foxglove over a WebSocket while the run goes on.

``lapwrench run --foxglove [HOST:PORT]`` starts foxglove-sdk's WebSocket server on the logger's
:class:`foxglove.Context`: every channel the MCAP file gets (cycles, wrench arrows, transforms,
joint states, scope pose, camera images, events) reaches a connected Foxglove app too, with the
same schemas, from the logger's writer thread (outside the 1 kHz cycle; with the real-time process
the loop runs in another process altogether). foxglove-sdk sends only what a client subscribed to.

The robot's URDF goes on :data:`ROBOT_DESCRIPTION_TOPIC` (``{"data": urdf}``, once a second of
wall-clock time, so a client that connects later gets it). Its mesh files are named ``package://lapwrench/<n>/<file>``
and served by the server's asset handler, which answers for exactly those files and nothing else.
Open Foxglove, "Open connection", ``ws://127.0.0.1:8765``, then import the layout
``lapwrench/data/foxglove/lapwrench.json`` (README, "Live telemetry").
"""

from __future__ import annotations

import math
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

ROBOT_DESCRIPTION_TOPIC = "/robot_description"
DESCRIPTION_SCHEMA = {"type": "object", "properties": {"data": {"type": "string"}}}
DESCRIPTION_PERIOD_S = 1.0  # wall-clock: a client that connects later gets it within a second
LiveAddress = tuple[str, int]  # (host, port), as lapwrench.cli_types.host_port parses it


class LiveError(RuntimeError):
    """The server could not start (port taken, host unknown)."""


def urdf_with_assets(urdf: str) -> tuple[str, dict[str, Path]]:
    """The URDF with each mesh named ``package://lapwrench/<i>/<file name>``, and those URIs → files."""
    root = ET.fromstring(urdf)
    assets: dict[str, Path] = {}
    by_path: dict[str, str] = {}
    for mesh in root.iter("mesh"):
        path = mesh.get("filename", "")
        if not path or path.startswith("package://"):
            continue
        if path not in by_path:
            by_path[path] = f"package://lapwrench/{len(by_path)}/{Path(path).name}"
            assets[by_path[path]] = Path(path)
        mesh.set("filename", by_path[path])
    return ET.tostring(root, encoding="unicode"), assets


class LiveServer:
    """foxglove-sdk's WebSocket server on a logging context, with the robot description and its meshes."""

    def __init__(self, context: Any, address: LiveAddress, urdf: str | None = None) -> None:
        import foxglove

        self.assets: dict[str, Path] = {}
        self.urdf: str | None = None
        if urdf is not None:
            self.urdf, self.assets = urdf_with_assets(urdf)
        try:
            self.server = foxglove.start_server(
                name="lapwrench", host=address[0], port=address[1], context=context, asset_handler=self._asset
            )
        except RuntimeError as exc:
            where = f"{address[0]}:{address[1]}"
            raise LiveError(f"cannot serve Foxglove on {where}: {str(exc).removeprefix('FoxgloveError: ')}") from exc
        self.address: LiveAddress = (address[0], self.server.port)
        self.description = (
            foxglove.Channel(ROBOT_DESCRIPTION_TOPIC, schema=DESCRIPTION_SCHEMA, context=context)
            if self.urdf is not None else None
        )
        self._next_wall = -math.inf

    def _asset(self, uri: str) -> bytes | None:
        """Only the meshes the published URDF names (any other URI: not found)."""
        path = self.assets.get(uri)
        if path is None:
            return None
        try:
            return path.read_bytes()
        except OSError:
            return None

    def publish_description(self, ns: int) -> None:
        """The URDF stamped ``ns``, at most once a second of wall-clock time (called from the writer thread)."""
        now = time.monotonic()
        if self.description is not None and now >= self._next_wall:
            self._next_wall = now + DESCRIPTION_PERIOD_S
            self.description.log({"data": self.urdf}, log_time=ns)

    def stop(self) -> None:
        self.server.stop()


IMAGE_PERIOD_S = 0.2  # camera frames go to the log and the live view at 5 Hz (session time)


def annotated_view(frame: Any, points: Any, cfg: Any, label: str) -> Any:
    """The laparoscope frame as the surgeon's assistant wants it live: the ε1/ε2 circles about the
    principal point (:func:`lapwrench.sim.video.annotate_frame`), the mode, and each detection."""
    import cv2
    import numpy as np

    from lapwrench.sim.video import annotate_frame

    img = annotate_frame(np.asarray(frame), cfg, label)
    for u, v in np.asarray(points if points is not None else np.zeros((0, 2)), dtype=float).reshape(-1, 2):
        if np.isfinite(u) and np.isfinite(v):
            cv2.circle(img, (round(u), round(v)), 6, (0, 255, 0), 2, cv2.LINE_AA)
    return img


class FrameTap:
    """The camera's newest frame to a run logger (the MCAP file and the live view) at 5 Hz, annotated
    with the detections and the mode of the latest logged cycle: ``lapwrench run --camera`` with
    ``--log`` or ``--foxglove``. A thread of the parent process, outside the 1 kHz loop's process;
    JPEG encoding happens on the writer thread (OpenCV releases the GIL there).

    ``buffer`` is the camera driver's latest-value buffer (samples stamped with ``time.monotonic``),
    ``t0`` the monotonic time of the session's start.
    """

    def __init__(self, buffer: Any, logger: Any, cfg: Any, t0: float) -> None:
        import threading

        self.buffer, self.logger, self.cfg, self.t0 = buffer, logger, cfg, t0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lapwrench-frame-tap", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        last = -1
        while not self._stop.wait(IMAGE_PERIOD_S):
            s = self.buffer.get()
            if s is None or s.seq == last:
                continue
            last = s.seq
            rec = self.logger.last_record
            points = None if rec is None else rec.instruments
            label = "" if rec is None else str(rec.mode)
            try:
                self.logger.image(s.timestamp - self.t0, annotated_view(s.value.image, points, self.cfg, label))
            except Exception:  # a malformed frame is not logged; the loop is not this thread's concern
                continue

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
