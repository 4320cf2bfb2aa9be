"""Asynchronous detection at the camera rate, with its latency, for the 1 kHz control loop.

The paper's detector runs at 25 fps (Sec. IV) while the controller ticks at 1 kHz. A frame captured
at time ``t`` yields its detections at ``t + latency``; until the next result arrives the loop
keeps using the latest one, stamped with its **capture** time, so the controller's input validator
can drop it once it is older than ``inputs.max_image_age`` (a detection that old counts as none).
No detection gives an empty ``(0, 2)`` point set: W_c = 0 (eq 8).

Two implementations with one interface (:meth:`offer`, :meth:`latest`, :meth:`observation`):

- :class:`SimulatedAsyncDetector`: deterministic, for simulation. Runs the detector synchronously
  on the captured frame but publishes the result only at ``capture_time + latency`` in simulation
  time. ``latency`` is a configured number of seconds, or ``"measured"``: the detector's wall time
  on that frame (realistic, but then not repeatable).
- :class:`ThreadedAsyncDetector`: a worker thread for real cameras. Frames offered while the
  worker is busy replace the pending one (the newest frame wins); the result is published as soon
  as it is computed, with the frame's capture stamp and the measured latency.

Typical simulation use, once per 1 ms tick::

    adet = SimulatedAsyncDetector(detector, frame_rate=25.0, latency=0.030)
    ...
    adet.offer(world.time, world.render)          # renders and detects only when a frame is due
    obs = adet.observation(world.time)            # InstrumentObservation(points, stamp=capture_time)
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lapwrench.perception.detection import Detection, Detector
from lapwrench.sensors import InstrumentObservation

FrameSource = np.ndarray | Callable[[], np.ndarray]


@dataclass(frozen=True)
class TimedDetections:
    """Detections of one frame: captured at ``capture_time``, available from ``available_time``.

    ``compute_time`` is the detector's wall time on the frame (s).
    """

    detections: tuple[Detection, ...]
    capture_time: float
    available_time: float
    compute_time: float

    @property
    def latency(self) -> float:
        """Capture-to-availability delay (s)."""
        return self.available_time - self.capture_time

    def age(self, now: float) -> float:
        """Time since capture (s) at ``now``."""
        return now - self.capture_time

    def points(self) -> np.ndarray:
        """Tracking image points ``(n, 2)`` (pixels), best score first."""
        return np.array([d.point for d in self.detections], dtype=float).reshape(-1, 2)


def _empty_points() -> np.ndarray:
    return np.zeros((0, 2), dtype=float)


COMPUTE_SAMPLES = 10_000  # detect() timings kept (400 s at 25 fps)


class _AsyncBase:
    def __init__(self, detector: Detector, frame_rate: float, max_age: float | None) -> None:
        if not (math.isfinite(frame_rate) and frame_rate > 0):
            raise ValueError(f"frame_rate must be a positive number (fps), got {frame_rate!r}")
        if max_age is not None and not (max_age > 0):
            raise ValueError(f"max_age must be positive seconds or None, got {max_age!r}")
        self.detector = detector
        self.frame_rate = float(frame_rate)
        self.period = 1.0 / self.frame_rate
        self.max_age = max_age
        self._next_capture: float | None = None
        self.frames_captured = 0

    def due(self, now: float) -> bool:
        """Whether a frame should be captured at ``now`` (first call: yes)."""
        return self._next_capture is None or now >= self._next_capture - 1e-9

    def _advance_schedule(self, now: float) -> None:
        if self._next_capture is None:
            self._next_capture = now + self.period
        else:  # keep the 25 fps grid; skip missed slots
            while self._next_capture <= now + 1e-9:
                self._next_capture += self.period
        self.frames_captured += 1

    def latest(self, now: float) -> TimedDetections | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def observation(self, now: float) -> InstrumentObservation:
        """The controller's input at ``now``: the latest detection's points, stamped at capture.

        Empty points (W_c = 0) when nothing is available yet, or when the latest result is older
        than ``max_age`` (if set; the controller's validator also applies ``inputs.max_image_age``).
        The stamp is the capture time of the latest result (or ``now`` when there is none).
        """
        res = self.latest(now)
        if res is None:
            return InstrumentObservation(_empty_points(), stamp=float(now))
        if self.max_age is not None and res.age(now) > self.max_age:
            return InstrumentObservation(_empty_points(), stamp=res.capture_time)
        return InstrumentObservation(res.points(), stamp=res.capture_time)


class SimulatedAsyncDetector(_AsyncBase):
    """Deterministic asynchronous detection in simulation time (see the module docstring).

    Args:
        detector: any :class:`Detector`.
        frame_rate: camera rate (fps); frames are captured on a grid starting at the first offer.
        latency: seconds from capture to availability, or ``"measured"`` (detector wall time).
        max_age: results older than this (s) give no points; ``None`` leaves it to the controller.
    """

    def __init__(
        self,
        detector: Detector,
        *,
        frame_rate: float = 25.0,
        latency: float | Literal["measured"] = 0.04,
        max_age: float | None = None,
    ) -> None:
        super().__init__(detector, frame_rate, max_age)
        if latency != "measured" and not (isinstance(latency, int | float) and math.isfinite(latency)
                                          and latency >= 0):
            raise ValueError(f"latency must be >= 0 seconds or 'measured', got {latency!r}")
        self.latency = latency
        self.compute_seconds: deque[float] = deque(maxlen=COMPUTE_SAMPLES)
        """Wall time of the latest ``detect`` calls (s), to report the detector's measured inference time
        (bounded: a long UI session would otherwise grow it by 25 a second)."""
        self._pending: deque[TimedDetections] = deque()
        self._latest: TimedDetections | None = None

    def offer(self, now: float, frame: FrameSource) -> bool:
        """Capture and detect ``frame`` at ``now`` if a frame is due; returns whether it was.

        ``frame`` may be an image or a callable producing one (called only when due, so rendering
        happens at the camera rate).
        """
        if not self.due(now):
            return False
        image = frame() if callable(frame) else frame
        t0 = time.perf_counter()
        dets = tuple(self.detector.detect(image))
        compute = time.perf_counter() - t0
        self.compute_seconds.append(compute)
        lat = compute if self.latency == "measured" else float(self.latency)
        self._pending.append(TimedDetections(dets, float(now), float(now) + lat, compute))
        self._advance_schedule(now)
        return True

    def latest(self, now: float) -> TimedDetections | None:
        """The newest result available at ``now`` (its ``available_time <= now``), or ``None``.

        Simulation time only moves forward: a result once published stays the latest until a
        newer one is published.
        """
        while self._pending and self._pending[0].available_time <= now + 1e-12:
            self._latest = self._pending.popleft()
        return self._latest

    def reset(self) -> None:
        self._pending.clear()
        self._latest = None
        self._next_capture = None
        self.frames_captured = 0


class ThreadedAsyncDetector(_AsyncBase):
    """Detection in a worker thread, for real cameras (see the module docstring).

    ``clock`` gives the time base of the capture stamps (default :func:`time.monotonic`; use the
    controller's clock). Use as a context manager or call :meth:`close`.
    """

    def __init__(
        self,
        detector: Detector,
        *,
        frame_rate: float = 25.0,
        max_age: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(detector, frame_rate, max_age)
        self.clock = clock
        self._cond = threading.Condition()
        self._pending_frame: tuple[np.ndarray, float] | None = None
        self._latest: TimedDetections | None = None
        self._error: BaseException | None = None
        self._closed = False
        self.frames_dropped = 0
        self._thread = threading.Thread(target=self._run, name="lapwrench-detector", daemon=True)
        self._thread.start()

    def offer(self, now: float | None, frame: FrameSource) -> bool:
        """Hand a frame captured at ``now`` (default: ``clock()``) to the worker if one is due."""
        now = self.clock() if now is None else float(now)
        if self._error is not None:
            raise RuntimeError(f"detector worker failed: {self._error}") from self._error
        if self._closed:
            raise RuntimeError("ThreadedAsyncDetector is closed")
        if not self.due(now):
            return False
        image = frame() if callable(frame) else frame
        with self._cond:
            if self._pending_frame is not None:
                self.frames_dropped += 1
            self._pending_frame = (image, now)
            self._cond.notify()
        self._advance_schedule(now)
        return True

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending_frame is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                assert self._pending_frame is not None  # the wait ends on a frame or on close
                image, stamp = self._pending_frame
                self._pending_frame = None
            try:
                t0 = time.perf_counter()
                dets = tuple(self.detector.detect(image))
                compute = time.perf_counter() - t0
            except BaseException as exc:  # surfaced on the next offer()
                self._error = exc
                return
            res = TimedDetections(dets, stamp, self.clock(), compute)
            with self._cond:
                self._latest = res
                self._cond.notify_all()

    def latest(self, now: float | None = None) -> TimedDetections | None:
        with self._cond:
            return self._latest

    def wait_for_result(self, capture_time: float, timeout: float = 5.0) -> TimedDetections | None:
        """Block until the result of the frame captured at ``capture_time`` (or a newer one) is in."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._latest is None or self._latest.capture_time < capture_time:
                if self._error is not None:
                    raise RuntimeError(f"detector worker failed: {self._error}") from self._error
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            return self._latest

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> ThreadedAsyncDetector:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
