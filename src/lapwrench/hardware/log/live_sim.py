"""Live telemetry of simulated runs: ``demo --foxglove`` and ``ui --foxglove`` (:func:`live_simulation`).

The simulation's loops are observed through :func:`lapwrench.sim.loop.observe_cycles`; each cycle
(decimated) becomes a :class:`~lapwrench.hardware.log.record.CycleRecord` for a
:class:`~lapwrench.hardware.log.RunLogger` that serves them live (:mod:`.live`) and writes no file.
"""

from __future__ import annotations

import contextlib
import sys
from typing import Any

from lapwrench.cli_types import listen_problem
from lapwrench.hardware.log.live import IMAGE_PERIOD_S, LiveAddress, LiveError, annotated_view
from lapwrench.hardware.log.record import cycle_record
from lapwrench.hardware.log.telemetry import TelemetryLayout, simulation_layout
from lapwrench.hardware.log.writer import RunLogger


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
        self._next_image = 0.0

    def frame(self, loop: Any, image: Any, t: float) -> None:
        """A laparoscope frame (5 Hz of session time) with the loop's latest detections; drawn here when
        the loop draws none (its detector, projected geometry, needs no image)."""
        if t < self._next_image:
            return
        self._next_image = t + IMAGE_PERIOD_S
        if image.size == 0:
            image = loop.world.render()
        obs = loop.detection.observation(t) if loop.detection is not None else None
        points = None if obs is None else obs.points
        self.logger.image(self._offset + t, annotated_view(image, points, loop.cfg, loop.last_mode))

    def __call__(self, loop: Any, cycle: Any) -> None:
        if id(loop) != self._loop_id:
            self._loop_id, self._offset, self._next_image = id(loop), self._last, 0.0
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
    stderr, prefixed with ``who``, as are the lines about its misbehaving clients (:class:`.live.IncidentLog`).

    ``telemetry`` is the cues whose telemetry the cycle messages carry (:mod:`.telemetry`): the
    caller's :func:`~.telemetry.simulation_layout` of the configuration it runs; by default that of no
    configuration (every registered cue type that logs telemetry, under its type name). A cue a cycle
    has values for but the layout does not name is left out of the message.
    """

    def __init__(self, address: LiveAddress, robot: str, who: str, telemetry: TelemetryLayout | None = None) -> None:
        from lapwrench.robot.model import RobotModel
        from lapwrench.sim.loop import observe_cycles

        problem = listen_problem(*address)
        if problem:
            raise LiveError(problem)
        layout = simulation_layout() if telemetry is None else telemetry
        meta = {"command": who, "robot": robot}
        self.logger = RunLogger(None, meta, model=RobotModel(robot), live=address, telemetry=dict(layout))
        assert self.logger.live is not None
        self.logger.live.incidents.who = who  # what its clients do wrong is told as this command's
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
