"""The run logger: bounded rings the loop appends to in O(1), and the writer thread that drains
them in short, paced rounds (see "Writing never blocks the control loop" in the package docstring)."""

from __future__ import annotations

import functools
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lapwrench.hardware.log.cycle_codec import encode_cycle
from lapwrench.hardware.log.frames import FrameSolver, ScopeFrames, finite_vector
from lapwrench.hardware.log.live import LiveAddress, LiveServer
from lapwrench.hardware.log.messages import (
    frame_transforms_message,
    image_message,
    joint_states_message,
    pose_message,
    wrench_scene_message,
)
from lapwrench.hardware.log.record import CycleRecord
from lapwrench.hardware.log.sink import MAX_LOG_TIME_S, McapSink, json_bytes, log_time_ns
from lapwrench.hardware.log.telemetry import checked_layout, layout_from_meta
from lapwrench.hardware.log.topics import META_TOPIC, STATS_TOPIC

if TYPE_CHECKING:
    from lapwrench.robot.model import RobotModel

CYCLE_CAPACITY = 4096  # records (4 s at 1 kHz)
EVENT_CAPACITY = 1024
IMAGE_CAPACITY = 4
TRANSFORM_RATE_HZ = 100.0
STATIC_EVERY = 100  # the fixed transforms go in every 100th frame set (1 Hz) and in the first
WRITE_BUDGET_S = 150e-6  # longest stretch of writing (GIL held) per round, plus the record in hand
PAUSE_BUSY_S = 300e-6  # sleep between rounds while records wait
PAUSE_IDLE_S = 1e-3  # sleep when the ring is empty


@dataclass
class LogCounters:
    """What the logger wrote and dropped (also written on ``/lapwrench/log_stats`` at close)."""

    cycles: int = 0
    dropped: int = 0
    events: int = 0
    dropped_events: int = 0
    images: int = 0
    dropped_images: int = 0
    transforms: int = 0
    errors: int = 0
    first_error: str | None = None
    bad_times: int = 0  # records, events and images whose time is no session time (written at the latest good one)
    first_bad_time: str | None = None


def _call(job: Callable[[], None]) -> None:
    job()


class RunLogger:
    """Writes a run to an MCAP file (foxglove-sdk) from a background thread.

    Args:
        path: Output ``.mcap`` file (parent folders are created; an existing file is replaced); None
            writes no file (with ``live``: telemetry only).
        meta: Written once on ``/lapwrench/meta``.
        model: The robot model. With it the writer adds the frame transforms, the scope pose and
            the wrench arrows (forward kinematics of the logged measured q, on the writer thread).
        capacity: Cycle records the ring holds before new ones are dropped (and counted).
        transform_rate_hz: Rate (session time) of the transforms, pose, joint states and arrows.
        live: Also serve every channel live to Foxglove at this address (:mod:`.live`; LiveError if
            the server cannot start), with the model's URDF.
        start: Start the writer thread now (default). With False, records queue in the rings (and
            overflow into the drop counters) until :meth:`start`; :meth:`close` starts it if needed.
        telemetry: The cues whose telemetry the cycle messages carry, cue name → field names
            (:mod:`.telemetry`; ValueError past its bounds). Default: the cues of the configuration
            in ``meta["config"]`` (what ``lapwrench run`` writes there), none without one.
    """

    def __init__(
        self,
        path: str | Path | None,
        meta: dict[str, Any] | None = None,
        *,
        model: RobotModel | None = None,
        capacity: int = CYCLE_CAPACITY,
        transform_rate_hz: float = TRANSFORM_RATE_HZ,
        live: LiveAddress | None = None,
        start: bool = True,
        telemetry: Mapping[str, Sequence[str]] | None = None,
    ) -> None:
        if capacity < 1 or not transform_rate_hz > 0:
            raise ValueError("capacity must be ≥ 1 and transform_rate_hz > 0")
        if path is None and live is None:
            raise ValueError("a RunLogger writes a file, serves live telemetry, or both")
        self.path = None if path is None else Path(path)
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self.capacity = capacity
        self.transform_rate_hz = transform_rate_hz
        self.counters = LogCounters()
        self.last_record: CycleRecord | None = None
        self.telemetry = layout_from_meta(meta) if telemetry is None else checked_layout(telemetry)
        self._solver = FrameSolver(model) if model is not None else None
        self._sink = McapSink(self.path, with_frames=self._solver is not None, telemetry=self.telemetry)
        self.live: LiveServer | None = None
        if live is not None:
            try:
                self.live = LiveServer(self._sink.context, live, None if model is None else model.urdf)
            except Exception:
                self._sink.close({})  # the file stays a valid (empty) MCAP
                raise
        self._ring: deque[CycleRecord] = deque()  # bounded by cycle(); appended by the loop only
        self._events: deque[tuple[float, str, str]] = deque()
        self._images: deque[tuple[float, Any, str]] = deque()
        self._next_frames_t = -math.inf
        self._jobs: deque[Callable[[], None]] = deque()  # steps of a frame set, one per round
        self._last_ns = 0  # log time of the latest cycle written (the closing messages get it)
        self._closing = threading.Event()
        self._closed = False
        if meta is not None:
            self._sink.write_json(META_TOPIC, 0, json_bytes(meta))
        self._thread = threading.Thread(target=self._run, name="lapwrench-mcap", daemon=True)
        if start:
            self._thread.start()

    def start(self) -> None:
        """Start the writer thread (when built with ``start=False``); idempotent."""
        if self._thread.ident is None and not self._closed:  # never started
            self._thread.start()

    # -- loop side: O(1), never blocks ----------------------------------------------------------
    def cycle(self, record: CycleRecord) -> None:
        """Hand one cycle to the writer (never blocks; dropped and counted when the ring is full)."""
        self.last_record = record  # what the camera frames are annotated with (FrameTap)
        if len(self._ring) < self.capacity:
            self._ring.append(record)
        else:
            self.counters.dropped += 1

    def event(self, time: float, kind: str, message: str) -> None:
        """Hand one event to the writer (never blocks; dropped and counted when its ring is full)."""
        if len(self._events) < EVENT_CAPACITY:
            self._events.append((float(time), str(kind), str(message)))
        else:
            self.counters.dropped_events += 1

    def image(self, t: float, frame: bytes | np.ndarray, fmt: str = "jpeg") -> None:
        """Hand one camera frame to the writer: encoded bytes (``fmt``: "jpeg", "png", ...) or an
        RGB/grey uint8 array (JPEG-encoded on the writer thread). The array must not change
        afterwards. Never blocks; dropped and counted when the ring (4 frames) is full."""
        if len(self._images) < IMAGE_CAPACITY:
            self._images.append((float(t), frame, fmt))
        else:
            self.counters.dropped_images += 1

    @property
    def dropped(self) -> int:
        """Cycle records dropped because the writer fell behind."""
        return self.counters.dropped

    @property
    def cycles(self) -> int:
        """Cycle records written so far."""
        return self.counters.cycles

    @property
    def events(self) -> int:
        """Events written so far."""
        return self.counters.events

    @property
    def errors(self) -> int:
        """Records or frames the writer could not write."""
        return self.counters.errors

    # -- writer thread ----------------------------------------------------------------------------
    def _run(self) -> None:
        """Write in short rounds, sleeping in between (each sleep hands the GIL to the loop):
        ``PAUSE_BUSY_S`` while work waits, ``PAUSE_IDLE_S`` when there is none."""
        while True:
            closing = self._closing.is_set()
            self._write_round()
            if self._ring or self._events or self._images or self._jobs:
                time.sleep(0.0 if closing else PAUSE_BUSY_S)
            elif closing:
                return
            else:
                time.sleep(PAUSE_IDLE_S)

    def _write_round(self) -> None:
        """One short stretch of work: one step of a due frame set alone, or the events, one
        image and cycle records until ``WRITE_BUDGET_S`` is used up or a frame set is due."""
        if self._jobs:
            self._guarded(_call, self._jobs.popleft())
            return
        deadline = time.perf_counter() + WRITE_BUDGET_S
        while self._events:
            self._guarded(self._write_event, self._events.popleft())
        if self._images:
            self._guarded(self._write_image, self._images.popleft())
        ring = self._ring
        while ring:
            self._guarded(self._write_cycle, ring.popleft())
            if self._jobs or time.perf_counter() > deadline:
                return

    def _guarded(self, write: Callable[[Any], None], item: Any) -> None:
        """Run one write; a bad record is counted (and the first error kept), never fatal."""
        try:
            write(item)
        except Exception as exc:
            c = self.counters
            c.errors += 1
            if c.first_error is None:
                c.first_error = f"{type(exc).__name__}: {exc}"

    def _log_ns(self, t: float) -> tuple[int, bool]:
        """The log time of a record, event or image at session time ``t``, and whether ``t`` was one: a
        time that is not (NaN, infinite, negative, past :data:`MAX_LOG_TIME_S`: foxglove-sdk refuses it,
        the record would be lost) is counted and the latest cycle's log time is used instead (a
        ``log_bad_time`` event at close says how many)."""
        ns = log_time_ns(t)
        if ns is not None:
            return ns, True
        c = self.counters
        c.bad_times += 1
        if c.first_bad_time is None:
            c.first_bad_time = repr(t)[:40]
        return self._last_ns, False

    def _write_event(self, ev: tuple[float, str, str]) -> None:
        self._sink.write_event(self._log_ns(ev[0])[0], *ev)
        self.counters.events += 1

    def _write_image(self, item: tuple[float, Any, str]) -> None:
        t, frame, fmt = item
        ns = self._log_ns(t)[0]
        self._sink.image_channel().log(image_message(ns, frame, fmt), log_time=ns)
        self.counters.images += 1

    def _write_cycle(self, rec: CycleRecord) -> None:
        """The cycle message. A cycle on the frame grid (session time, 1 µs of slack for rounding)
        with a finite measured q also queues its frame set, written in the next rounds; a cycle without
        a session time (:meth:`_log_ns`) is written with its fields as they are, and has no frame set."""
        ns, timed = self._log_ns(rec.t)
        self._sink.cycle.log(encode_cycle(rec, self.telemetry), ns)
        if self.live is not None:
            self.live.publish_description(ns)
        self.counters.cycles += 1
        self._last_ns = max(self._last_ns, ns)
        if timed and rec.t >= self._next_frames_t - 1e-6 and not self._jobs:
            q = finite_vector(rec.q)
            if q is not None and (self._solver is None or len(q) == self._solver.nq):
                self._next_frames_t = (math.floor(rec.t * self.transform_rate_hz + 1e-3) + 1) / self.transform_rate_hz
                self._jobs.append(functools.partial(self._frames_step1, rec, q, ns))

    def _frames_step1(self, rec: CycleRecord, q: np.ndarray, ns: int) -> None:
        """Forward kinematics of the measured q, the transforms and the scope pose; then the
        second step is queued. Without a model, the joint states only."""
        sink, solver = self._sink, self._solver
        if solver is None:
            names = [f"joint{j + 1}" for j in range(len(q))]
            sink.joints.log(joint_states_message(ns, names, q, rec.dq, rec.tau_J), log_time=ns)
            return
        frames = solver.solve(q, rec.p_R, rec.p_G, self._static_due())
        assert frames is not None and sink.tf is not None and sink.pose is not None
        sink.tf.log(frame_transforms_message(ns, frames.placements), log_time=ns)
        sink.pose.log(pose_message(ns, frames.pose_E), log_time=ns)
        self.counters.transforms += 1
        self._jobs.append(functools.partial(self._frames_step2, rec, q, frames, ns))

    def _frames_step2(self, rec: CycleRecord, q: np.ndarray, frames: ScopeFrames, ns: int) -> None:
        """The joint states and the wrench arrows of a frame set."""
        sink, solver = self._sink, self._solver
        assert solver is not None and sink.wrenches is not None
        sink.joints.log(joint_states_message(ns, solver.joint_names, q, rec.dq, rec.tau_J), log_time=ns)
        sink.wrenches.log(wrench_scene_message(ns, solver.base, rec.wrenches, frames.anchors), log_time=ns)

    def _static_due(self) -> bool:
        """The fixed transforms go in the first frame set and every ``STATIC_EVERY``-th."""
        return self.counters.transforms % STATIC_EVERY == 0

    # -- closing ----------------------------------------------------------------------------------
    def stats(self) -> dict[str, Any]:
        """The counters (and the ring's capacity and the transform rate) as a dict."""
        c = self.counters
        return {
            "cycles": c.cycles,
            "dropped": c.dropped,
            "events": c.events,
            "dropped_events": c.dropped_events,
            "images": c.images,
            "dropped_images": c.dropped_images,
            "transforms": c.transforms,
            "errors": c.errors,
            "first_error": c.first_error,
            "bad_times": c.bad_times,
            "first_bad_time": c.first_bad_time,
            "capacity": self.capacity,
            "transform_rate_hz": self.transform_rate_hz,
        }

    def close(self) -> None:
        """Flush the rings, write the stats (and a ``log_dropped`` event if anything was
        dropped) and finish the file. Idempotent."""
        if self._closed:
            return
        self._closing.set()
        self.start()  # a logger never started still writes what it holds
        self._closed = True
        self._thread.join()
        stats = self.stats()
        ns = self._last_ns
        lost = stats["dropped"] + stats["dropped_events"] + stats["dropped_images"]
        if lost:
            msg = (
                f"the logger dropped {stats['dropped']} cycles, {stats['dropped_events']} events and "
                f"{stats['dropped_images']} images (writer behind)"
            )
            self._guarded(self._write_event, (ns / 1e9, "log_dropped", msg))
            stats = self.stats()
        if stats["bad_times"]:
            msg = (f"{stats['bad_times']} records, events or images had a time that is no session time (0 to "
                   f"{MAX_LOG_TIME_S:.0f} s; the first: {stats['first_bad_time']}): written at the latest cycle's time")
            self._guarded(self._write_event, (ns / 1e9, "log_bad_time", msg))
            stats = self.stats()
        self._sink.write_json(STATS_TOPIC, ns, json_bytes(stats))
        self._sink.close(stats)
        if self.live is not None:
            self.live.stop()

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
