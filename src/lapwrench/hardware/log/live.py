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

A client that sends garbage (malformed JSON, unknown ops, binary junk, a frame over the size limit, a
broken handshake, a connection dropped mid-message) is foxglove-sdk's to refuse; what its Rust core
logs about it (through Python's :mod:`logging`, under the ``foxglove`` logger) becomes one line per
incident on stderr, ``lapwrench run: Foxglove server: ignored a malformed message from
127.0.0.1:53412: ...``, at most :data:`INCIDENT_BURST` lines in :data:`INCIDENT_WINDOW_S` seconds
(:class:`IncidentLog`, :class:`FoxgloveLog`), so a flood of garbage cannot fill the terminal.
:mod:`lapwrench.ui.untrusted` does the same for the page's viser server.
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import sys
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROBOT_DESCRIPTION_TOPIC = "/robot_description"
DESCRIPTION_SCHEMA = {"type": "object", "properties": {"data": {"type": "string"}}}
DESCRIPTION_PERIOD_S = 1.0  # wall-clock: a client that connects later gets it within a second
LiveAddress = tuple[str, int]  # (host, port), as lapwrench.cli_types.host_port parses it


INCIDENT_BURST = 5  # lines about misbehaving network clients, at most, in each window...
INCIDENT_WINDOW_S = 10.0  # ...of this many seconds (wall clock): a flood cannot fill the terminal
INCIDENT_CHARS = 200  # an incident's line is cut to this many characters


class LiveError(RuntimeError):
    """The server could not start (port taken, host unknown)."""


class IncidentLog:
    """One line on stderr, ``<who>: <what>``, for each thing a network client did wrong (a malformed
    message, a broken handshake, a connection dropped mid-frame): the servers survive such input, and
    the operator is told in one line rather than a library's traceback.

    At most ``burst`` lines are printed in each ``window`` seconds of ``clock``; the incidents held back
    are counted, and the next line printed (or :meth:`close`) says how many. Thread-safe: the servers
    report from their own threads.
    """

    def __init__(self, who: str, burst: int = INCIDENT_BURST, window: float = INCIDENT_WINDOW_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if burst < 1 or not window > 0:
            raise ValueError("an incident log prints at least one line per window of a positive length")
        self.who, self.burst, self.window, self.clock = who, burst, window, clock
        self.total = 0  # incidents reported so far
        self.printed = 0  # lines printed so far
        self.held_back = 0  # incidents not printed since the last line
        self._lock = threading.Lock()
        self._window_start = -math.inf
        self._in_window = 0

    def report(self, what: str) -> bool:
        """Print ``<who>: <what>`` (on one line, cut to :data:`INCIDENT_CHARS`) unless this window's
        lines are used up; True if it was printed."""
        with self._lock:
            self.total += 1
            now = self.clock()
            if now - self._window_start >= self.window:
                self._window_start, self._in_window = now, 0
            if self._in_window >= self.burst:
                self.held_back += 1
                return False
            self._in_window += 1
            line = one_line(f"{self.who}: {what}")
            if self.held_back:
                line += f" (and {self.held_back} more not shown)"
                self.held_back = 0
            self.printed += 1
            say(line)
            return True

    def close(self) -> None:
        """Say how many incidents were held back since the last line, if any (at the server's end)."""
        with self._lock:
            if self.held_back:
                say(f"{self.who}: {self.held_back} more incidents from network clients not shown")
                self.held_back = 0


def say(line: str) -> None:
    """``line`` on stderr; nothing if stderr is gone (a closed pipe): a client's garbage must not turn
    into an error of the thread that reports it."""
    with contextlib.suppress(OSError, ValueError):
        print(line, file=sys.stderr, flush=True)


def one_line(text: str, limit: int = INCIDENT_CHARS) -> str:
    """``text`` on one printable line of at most ``limit`` characters (a client chooses what its
    garbage says, control characters and all)."""
    flat = "".join(c if c.isprintable() else " " for c in text)
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


FOXGLOVE_LOGGER = "foxglove"  # foxglove-sdk's Rust core logs through Python's logging, under this name
FOXGLOVE_FORMS = (  # what it logs about a client -> lapwrench's words
    (re.compile(r"Invalid message from (\S+): (.*)", re.DOTALL), "ignored a malformed message from {}: {}"),
    (re.compile(r"Error receiving from client (\S+): (.*)", re.DOTALL), "dropped the connection of {}: {}"),
    (re.compile(r"Dropping client (\S+): (.*)", re.DOTALL), "refused a connection from {}: {}"),
)


def foxglove_incident(message: str) -> str:
    """A line of foxglove-sdk's server log in lapwrench's words (another line: as it is)."""
    for pattern, form in FOXGLOVE_FORMS:
        m = pattern.fullmatch(message)
        if m is not None:
            return "Foxglove server: " + form.format(*m.groups())
    return f"Foxglove server: {message}"


class FoxgloveLog(logging.Handler):
    """foxglove-sdk's server log (its warnings and errors) on the ``foxglove`` logger, as
    :class:`IncidentLog` lines of the newest live server, while at least one runs: a line about a
    client in lapwrench's words (:func:`foxglove_incident`), any other as foxglove says it.

    A handler on foxglove's own logger, not a change of the process's logging: with no logging set up
    (the command line), Python's last-resort handler is no longer used for these records, so each is
    printed once, in lapwrench's words and rate-limited; a logging configuration set up by whoever
    embeds lapwrench still gets them. One for the process (:data:`FOXGLOVE_LOG`): foxglove's records do
    not say which server they are about.
    """

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.logs: list[IncidentLog] = []
        self._attach_lock = threading.Lock()

    def emit(self, record: logging.LogRecord) -> None:
        logs = self.logs
        if logs:
            logs[-1].report(foxglove_incident(record.getMessage()))

    def attach(self, log: IncidentLog) -> None:
        """A live server starts: its incidents go to ``log``."""
        with self._attach_lock:
            self.logs = [*self.logs, log]
            logger = logging.getLogger(FOXGLOVE_LOGGER)
            if self not in logger.handlers:
                logger.addHandler(self)

    def detach(self, log: IncidentLog) -> None:
        """A live server stopped; the last one takes the handler off foxglove's logger."""
        with self._attach_lock:
            self.logs = [x for x in self.logs if x is not log]
            if not self.logs:
                logging.getLogger(FOXGLOVE_LOGGER).removeHandler(self)


FOXGLOVE_LOG = FoxgloveLog()


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
    """foxglove-sdk's WebSocket server on a logging context, with the robot description and its meshes.

    What its clients do wrong is told on stderr by :attr:`incidents` (one line each, rate-limited),
    prefixed with its ``who``: ``lapwrench run`` by default (which builds it through
    :class:`~lapwrench.hardware.log.RunLogger`); the simulated runs set their own (:mod:`.live_sim`).
    """

    def __init__(self, context: Any, address: LiveAddress, urdf: str | None = None) -> None:
        import foxglove

        self.assets: dict[str, Path] = {}
        self.urdf: str | None = None
        if urdf is not None:
            self.urdf, self.assets = urdf_with_assets(urdf)
        self.incidents = IncidentLog("lapwrench run")
        FOXGLOVE_LOG.attach(self.incidents)
        try:
            self.server = foxglove.start_server(
                name="lapwrench", host=address[0], port=address[1], context=context, asset_handler=self._asset
            )
        except BaseException as exc:  # Ctrl-C included: the handler does not outlive a failed start
            FOXGLOVE_LOG.detach(self.incidents)
            if not isinstance(exc, RuntimeError):
                raise
            where = f"{address[0]}:{address[1]}"
            raise LiveError(f"cannot serve Foxglove on {where}: {str(exc).removeprefix('FoxgloveError: ')}") from exc
        self.address: LiveAddress = (address[0], self.server.port)
        try:
            self.description = (
                foxglove.Channel(ROBOT_DESCRIPTION_TOPIC, schema=DESCRIPTION_SCHEMA, context=context)
                if self.urdf is not None else None
            )
        except BaseException:
            self.stop()
            raise
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
        try:
            self.server.stop()
        finally:
            FOXGLOVE_LOG.detach(self.incidents)
            self.incidents.close()


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
