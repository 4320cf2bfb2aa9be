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

import contextlib
import math
import sys
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


class SimTelemetry:
    """Streams the cycles of simulated runs to a (live) :class:`~lapwrench.hardware.log.RunLogger`:
    an observer for :func:`lapwrench.sim.loop.observe_cycles` (``demo --foxglove``, ``ui --foxglove``).

    The simulation runs faster than real time, so one cycle in ``every`` is sent (the events of every
    cycle are). Each new loop (a scenario, a run of it) continues the log's clock where the previous
    one ended, so the timeline never runs backwards.
    """

    def __init__(self, logger: Any, every: int = 10) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.logger = logger
        self.every = every
        self._loop_id: int | None = None
        self._offset = 0.0
        self._last = 0.0

    def __call__(self, loop: Any, cycle: Any) -> None:
        from lapwrench.hardware.log.record import cycle_record

        if id(loop) != self._loop_id:
            self._loop_id, self._offset = id(loop), self._last
        t = self._offset + cycle.frame.time
        self._last = max(self._last, t)
        for e in cycle.events:
            self.logger.event(self._offset + e.time, e.kind, e.message)
        if cycle.k % self.every:
            return
        sup = loop.supervisor
        rec = cycle_record(cycle, sup.state.value, sup.alarm)
        if rec is not None:
            rec.t = t
            self.logger.cycle(rec)


class live_simulation(contextlib.AbstractContextManager["live_simulation"]):  # noqa: N801 (used as a function)
    """Every simulated cycle (decimated, :class:`SimTelemetry`) served live to Foxglove on ``address``
    while the ``with`` block runs: ``demo --foxglove`` and ``ui --foxglove``. The server starts here
    (LiveError, one line, if it cannot: the port taken, the host unknown) and says where it listens on
    stderr, prefixed with ``who``."""

    def __init__(self, address: LiveAddress, robot: str, who: str) -> None:
        from lapwrench.cli_types import listen_problem
        from lapwrench.hardware.log.writer import RunLogger
        from lapwrench.robot.model import RobotModel
        from lapwrench.sim.loop import observe_cycles

        problem = listen_problem(*address)
        if problem:
            raise LiveError(problem)
        self.logger = RunLogger(None, {"command": who, "robot": robot}, model=RobotModel(robot), live=address)
        assert self.logger.live is not None
        host, port = self.logger.live.address
        print(f"{who}: live telemetry for Foxglove on ws://{host}:{port}", file=sys.stderr)
        self._observing = observe_cycles(SimTelemetry(self.logger))

    def __enter__(self) -> live_simulation:
        self._observing.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self._observing.__exit__(*exc)  # type: ignore[arg-type]
        finally:
            self.logger.close()
